//! The device's int8 model as `track` and `register --scene` load it: the
//! given blob or the shipped one, checked to be int8, with the template
//! file bound in place of its own, and the device options from the flags.

use std::path::Path;

use anyhow::Context;
use pcrnet_core::{Int8Model, Options};
use pcrnet_eval::cli::MethodOptions;
use pcrnet_eval::methods::{Method, MethodKind};

use crate::register::{Reading, shipped_model};
use pcrnet_core::registration::{MAX_CALIBRATED, NOISE_ALLOWANCE, max_residual_for};

/// A loaded device model.
pub(crate) struct DeviceModel {
    /// The blob, the template file bound in when one was given.
    pub(crate) blob: Vec<u8>,
    /// Which model, for messages.
    pub(crate) label: String,
    /// Whether it is the shipped embedded default.
    pub(crate) shipped: bool,
    /// The template file's local origin (its median; zero without a file).
    pub(crate) origin: [f64; 3],
    /// Template points given (zero without a file).
    pub(crate) template_points: usize,
    /// The method the flags describe.
    pub(crate) method: Method,
    /// The device options, counts as the blob was trained when not given
    /// (`register::or_trained`).
    pub(crate) options: Options,
    /// The template's residual floor: the one binding the template file
    /// measured (`pcrnet_train::floor`), or the blob's own without a file;
    /// `None` when neither has one (a file with fewer than twice the
    /// stored points, or a blob before format 6).
    pub(crate) floor: Option<f32>,
}

impl DeviceModel {
    /// Reads the model and binds `template` (read as `reading` says, about
    /// its own median) into it. `command` names the subcommand in messages.
    pub(crate) fn load(
        options: &MethodOptions,
        template: Option<&Path>,
        reading: &Reading,
        command: &str,
    ) -> anyhow::Result<Self> {
        let (blob, label, shipped) = match options.read_model()? {
            Some(blob) => (
                blob,
                options
                    .model
                    .clone()
                    .unwrap_or_default()
                    .display()
                    .to_string(),
                false,
            ),
            None => {
                let (blob, name) =
                    shipped_model(MethodKind::Device).context("no shipped int8 model in pcrnet")?;
                (blob.to_vec(), name.to_string(), true)
            }
        };
        if let Err(e) = Int8Model::from_bytes(&blob) {
            return Err(match e {
                pcrnet_core::Error::WrongKind { .. } => anyhow::anyhow!(
                    "{label}: not an int8 model blob; {command} runs the device's int8 model: give --model the int8 blob (`pcrnet export` writes both; the shipped one is models/embedded-default-int8.pcrn)"
                ),
                e => anyhow::Error::new(e).context(label),
            });
        }
        options.check_hypotheses(MethodKind::Device, Some(&blob), template.is_some())?;
        if let Some(warning) = options.mode_warning(MethodKind::Device, Some(&blob)) {
            eprintln!("warning: {warning}");
        }
        let method = options.method(MethodKind::Device);
        let (blob, origin, template_points) = match template {
            Some(path) => {
                let cloud = reading.load(path, None)?;
                let bound =
                    pcrnet_train::template::bind(&blob, &cloud.points, method.template_points)
                        .with_context(|| format!("binding {} into {label}", path.display()))?;
                (bound, cloud.origin, cloud.points.len())
            }
            None => (blob, [0.0; 3], 0),
        };
        let (device, floor) = {
            let model = Int8Model::from_bytes(&blob).with_context(|| label.clone())?;
            let mut device = pcrnet_eval::register::or_trained(
                &method.device_options(),
                model.trained_options(),
            );
            let floor = model.residual_floor();
            device.max_residual = verdict(options, floor, device.max_residual);
            (device, floor)
        };
        Ok(DeviceModel {
            blob,
            label,
            shipped,
            origin,
            template_points,
            method,
            options: device,
            floor,
        })
    }

    /// [`floor_line`] of this model's floor and verdict.
    pub(crate) fn floor_line(&self) -> Option<String> {
        floor_line(self.floor, self.options.max_residual)
    }

    /// The line saying which model runs.
    pub(crate) fn model_line(&self) -> String {
        if self.shipped {
            format!(
                "model: the shipped embedded default ({}, built into pcrnet; --model FILE to use another)",
                self.label
            )
        } else {
            format!("model: {}", self.label)
        }
    }
}

/// The device pipeline's verdict threshold: `in_force` (the flag's or the
/// default) calibrated by the template's residual `floor`
/// ([`max_residual_for`]) when there is one and `--max-residual` was not
/// given. The rule of `register`, `track` and `register --scene`.
pub(crate) fn verdict(options: &MethodOptions, floor: Option<f32>, in_force: f32) -> f32 {
    match (options.max_residual, floor) {
        (None, Some(floor)) => max_residual_for(floor, in_force),
        _ => in_force,
    }
}

/// `v` as the f64 its shortest decimal form reads as (`0.015`, not the
/// f32's `0.014999999664723873`), for JSON.
pub(crate) fn short(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::NAN)
}

/// What a template's residual `floor` says of the verdict `threshold` in
/// force, for a person: the floor, whether the verdict was calibrated by
/// it, and a warning when right poses would score above the verdict.
/// `None` without a floor.
pub(crate) fn floor_line(floor: Option<f32>, threshold: f32) -> Option<String> {
    let floor = floor?;
    let default = Options::default().max_residual;
    let calibrated = max_residual_for(floor, default);
    let capped = if floor + NOISE_ALLOWANCE > MAX_CALIBRATED {
        format!(
            "; a floor this high usually means a noisy or cluttered template file (the calibrated verdict stops at {MAX_CALIBRATED}): give a clean sample of the object's surface"
        )
    } else {
        String::new()
    };
    let measured = format!(
        "template residual floor: {floor:.4} of its size (its points beyond those stored, at its own pose){capped}"
    );
    Some(if threshold < calibrated {
        format!(
            "{measured}: with the noise a right pose may score above the verdict's --max-residual {threshold} and be marked not reliable; the blob's own verdict, {calibrated:.4}, is calibrated for it (leave --max-residual out to use it; docs/tracking.md)"
        )
    } else if calibrated > default && threshold == calibrated {
        format!(
            "{measured}: the verdict is calibrated for it, --max-residual {calibrated:.4} instead of {default} (the floor plus {NOISE_ALLOWANCE} for the noise; pass --max-residual {default} for the default; docs/tracking.md)"
        )
    } else {
        format!("{measured}, within the verdict's --max-residual {threshold}")
    })
}

/// The residual floor of the device model `blob` with `template` (if
/// given) bound in as `template_points` stored points: the floor binding
/// stores ([`pcrnet_train::template::Reference::residual_floor`]), or the
/// blob's own (int8 or f32). `None` when neither has one.
pub(crate) fn device_floor(
    blob: &[u8],
    template: Option<&[[f32; 3]]>,
    template_points: usize,
) -> Option<f32> {
    match template {
        Some(t) => pcrnet_train::template::Reference::new(t, template_points)
            .ok()?
            .residual_floor(),
        None => match Int8Model::from_bytes(blob) {
            Ok(m) => m.residual_floor(),
            Err(_) => pcrnet_core::F32Model::from_bytes(blob)
                .ok()?
                .residual_floor(),
        },
    }
}
