//! The registration methods compared, behind one dispatch ([`run`]) used
//! by `pcrnet register`, `pcrnet eval` and every experiment.
//!
//! | method | what runs | model |
//! |---|---|---|
//! | `pcrnet` | one network pass | int8 or f32 blob |
//! | `ipcrnet` | up to [`Method::iterations`] passes (the paper: 20), stopping when `\|\|dT - I\|\|_F <` [`Method::tolerance`] (the paper: 1e-7) | int8 or f32 blob |
//! | `pointnetlk` | inverse-compositional Lucas-Kanade on the encoder's features, up to 20 steps | f32 blob |
//! | `icp` | point-to-point ICP from the identity, up to 100 iterations | none |
//! | `device` | the device pipeline: network passes ([`Method::iterations`]), PointNetLK steps ([`Method::lk_iterations`]), [`Method::hypotheses`] starting poses, ICP against the blob's template points, residual (`pcrnet-core`'s `register`) | int8 or f32 blob |
//!
//! Any network method can be followed by host ICP refinement
//! ([`Method::refine_icp`]): ICP (f64, k-d tree, all template points)
//! starts from the network's pose.
//!
//! Time per registration ([`Outcome::seconds`]) is everything from the two
//! clouds to the pose on one thread: normalisation, the template's feature
//! (or PointNetLK's Jacobian, or ICP's k-d tree) and the iterations. The
//! paper's PCRNet also encodes both clouds per registration.

use std::borrow::Cow;
use std::time::Instant;

use pcrnet_core::{Degeneracy, Pose};
use serde::{Deserialize, Serialize};

use super::icp::{IcpConfig, IcpError, icp};
use crate::register::{
    ITERATIVE_TOLERANCE, Precision, network, pipeline, pipeline_viewed, register_pointnetlk,
};
use pcrnet_train::degeneracy::source_degeneracy;
use pcrnet_train::template::{DEFAULT_TEMPLATE_POINTS, Reference, TemplateError, bind_reference};

/// A method family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum MethodKind {
    /// One network pass (PCRNet).
    Pcrnet,
    /// Iterative network passes (i-PCRNet).
    Ipcrnet,
    /// Lucas-Kanade on the encoder's features (PointNetLK).
    Pointnetlk,
    /// Point-to-point ICP.
    Icp,
    /// The device pipeline: network, flip hypotheses, on-device ICP, residual.
    Device,
}

/// The name `--method` takes (`pcrnet`, `ipcrnet`, `pointnetlk`, `icp`,
/// `device`).
impl std::fmt::Display for MethodKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use clap::ValueEnum;
        match self.to_possible_value() {
            Some(v) => f.write_str(v.get_name()),
            None => write!(f, "{self:?}"),
        }
    }
}

/// What the device pipeline's ICP minimises (`pcrnet_core::Metric`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
pub enum DeviceMetric {
    /// To the tangent plane at the nearest template point.
    #[default]
    PointToPlane,
    /// To the nearest template point.
    PointToPoint,
}

impl From<DeviceMetric> for pcrnet_core::Metric {
    fn from(m: DeviceMetric) -> Self {
        match m {
            DeviceMetric::PointToPlane => pcrnet_core::Metric::PointToPlane,
            DeviceMetric::PointToPoint => pcrnet_core::Metric::PointToPoint,
        }
    }
}

/// A method with its settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Method {
    /// Which family.
    pub kind: MethodKind,
    /// Most passes (i-PCRNet), steps (PointNetLK) or iterations (ICP); 1 for
    /// PCRNet; for the device pipeline, network passes (0: as the blob was trained).
    pub iterations: usize,
    /// Refine the network's pose with ICP (network methods only).
    pub refine_icp: bool,
    /// i-PCRNet stops once a pass's `||dT - I||_F` is below this.
    pub tolerance: f32,
    /// Starting poses of the device pipeline (1 + template turns tried).
    #[serde(default = "default_hypotheses")]
    pub hypotheses: usize,
    /// Most ICP iterations of the device pipeline.
    #[serde(default = "default_icp_iterations")]
    pub icp_iterations: usize,
    /// ICP iterations of every hypothesis before the two best go on (a
    /// turned one far above the best after 3 of them is dropped).
    #[serde(default = "default_screen_iterations")]
    pub screen_iterations: usize,
    /// Most source points the device pipeline scores and refines.
    #[serde(default = "default_max_points")]
    pub max_points: usize,
    /// Most source points each network pass and LK step of the device
    /// pipeline encodes (0: as many as the blob's template feature was
    /// pooled over, `registration::network_points`).
    #[serde(default = "default_network_points")]
    pub network_points: usize,
    /// What the device pipeline's ICP minimises.
    #[serde(default)]
    pub metric: DeviceMetric,
    /// Device ICP pair distance (model units: share of the template's size).
    #[serde(default = "default_icp_distance")]
    pub icp_distance: f32,
    /// Device ICP stops once an update's `||dT - I||_F` is below this.
    #[serde(default = "default_icp_tolerance")]
    pub icp_tolerance: f32,
    /// The device residual's cap and the fitness's inlier radius (model
    /// units).
    #[serde(default = "default_inlier_distance")]
    pub inlier_distance: f32,
    /// The device pipeline calls a pose reliable when its relative plane
    /// residual is at most this.
    #[serde(default = "default_max_residual")]
    pub max_residual: f32,
    /// Template points the device pipeline stores when a template cloud is
    /// bound in place of the blob's own (it checks and refines poses
    /// against them).
    #[serde(default = "default_template_points")]
    pub template_points: usize,
    /// PointNetLK steps of the device pipeline after its network passes
    /// (0: none; a blob without a head, a model trained as PointNetLK,
    /// then runs as many as it was trained for). Needs a blob with
    /// PointNetLK's solver.
    #[serde(default)]
    pub lk_iterations: usize,
    /// The device pipeline's pose is reliable only if it also passes the
    /// check against the single view from the pair's viewpoint
    /// ([`pcrnet_core::scene::view`]); needs a viewpoint.
    #[serde(default)]
    pub view_check: bool,
}

fn default_hypotheses() -> usize {
    pcrnet_core::Options::default().hypotheses
}

fn default_icp_iterations() -> usize {
    pcrnet_core::Options::default().icp_iterations
}

fn default_screen_iterations() -> usize {
    pcrnet_core::Options::default().screen_iterations
}

fn default_max_points() -> usize {
    pcrnet_core::Options::default().max_points
}

/// 0: the blob's own ([`crate::register::or_trained`]).
fn default_network_points() -> usize {
    0
}

fn default_icp_distance() -> f32 {
    pcrnet_core::Options::default().icp_distance
}

fn default_icp_tolerance() -> f32 {
    pcrnet_core::Options::default().icp_tolerance
}

fn default_inlier_distance() -> f32 {
    pcrnet_core::Options::default().inlier_distance
}

fn default_max_residual() -> f32 {
    pcrnet_core::Options::default().max_residual
}

fn default_template_points() -> usize {
    DEFAULT_TEMPLATE_POINTS
}

impl Method {
    /// `kind` with the paper's iteration limit (PCRNet 1, i-PCRNet 20,
    /// PointNetLK 20, ICP 100) and i-PCRNet stop rule
    /// ([`ITERATIVE_TOLERANCE`]); no refinement.
    pub fn new(kind: MethodKind) -> Self {
        let iterations = match kind {
            MethodKind::Pcrnet => 1,
            // The passes the blob was trained for.
            MethodKind::Device => 0,
            MethodKind::Ipcrnet | MethodKind::Pointnetlk => 20,
            MethodKind::Icp => IcpConfig::default().max_iterations,
        };
        Method {
            kind,
            iterations,
            refine_icp: false,
            tolerance: ITERATIVE_TOLERANCE,
            hypotheses: default_hypotheses(),
            icp_iterations: default_icp_iterations(),
            screen_iterations: default_screen_iterations(),
            max_points: default_max_points(),
            network_points: default_network_points(),
            metric: DeviceMetric::default(),
            icp_distance: default_icp_distance(),
            icp_tolerance: default_icp_tolerance(),
            inlier_distance: default_inlier_distance(),
            max_residual: default_max_residual(),
            template_points: default_template_points(),
            lk_iterations: 0,
            view_check: false,
        }
    }

    /// The device pipeline on a PointNetLK blob: 20 LK steps (as the
    /// host's PointNetLK) alone (one start, scored, no ICP), or followed
    /// by the default hypotheses and device ICP.
    pub fn device_lk(then_icp: bool) -> Method {
        let device = Method::new(MethodKind::Device);
        Method {
            lk_iterations: 20,
            hypotheses: if then_icp { device.hypotheses } else { 1 },
            icp_iterations: if then_icp { device.icp_iterations } else { 0 },
            ..device
        }
    }

    /// The device pipeline's options for this method.
    pub fn device_options(&self) -> pcrnet_core::Options {
        pcrnet_core::Options {
            passes: self.iterations,
            lk_iterations: self.lk_iterations,
            tolerance: self.tolerance,
            hypotheses: self.hypotheses,
            icp_iterations: self.icp_iterations,
            screen_iterations: self.screen_iterations,
            max_points: self.max_points,
            network_points: self.network_points,
            metric: self.metric.into(),
            icp_distance: self.icp_distance,
            icp_tolerance: self.icp_tolerance,
            inlier_distance: self.inlier_distance,
            max_residual: self.max_residual,
        }
    }

    /// The same method followed by ICP.
    pub fn then_icp(self) -> Self {
        Method {
            refine_icp: true,
            ..self
        }
    }

    /// Whether the method needs a model blob.
    pub fn needs_model(&self) -> bool {
        self.kind != MethodKind::Icp
    }

    /// A display name: `i-PCRNet int8 + ICP`, `PointNetLK`, ...
    pub fn name(&self, precision: Option<Precision>) -> String {
        let base = match self.kind {
            MethodKind::Pcrnet => "PCRNet",
            MethodKind::Ipcrnet => "i-PCRNet",
            MethodKind::Pointnetlk => "PointNetLK",
            MethodKind::Icp => "ICP",
            MethodKind::Device if self.lk_iterations > 0 => match self.iterations {
                0 => "device PointNetLK",
                1 => "device PCRNet + LK",
                _ => "device i-PCRNet + LK",
            },
            MethodKind::Device if self.iterations > 1 => "device i-PCRNet",
            MethodKind::Device if self.iterations == 1 => "device PCRNet",
            // As many passes as the blob was trained for.
            MethodKind::Device => "device pipeline",
        };
        let precision = match (self.kind, precision) {
            (MethodKind::Icp | MethodKind::Pointnetlk, _) | (_, None) => String::new(),
            (_, Some(Precision::Int8)) => " int8".into(),
            (_, Some(Precision::F32)) => " f32".into(),
        };
        let precision = if self.kind == MethodKind::Device {
            let metric = match self.metric {
                DeviceMetric::PointToPlane => "",
                DeviceMetric::PointToPoint => " (point-to-point)",
            };
            let mut points = if self.max_points == default_max_points() {
                String::new()
            } else {
                format!(", {} points", self.max_points)
            };
            if self.network_points != default_network_points() {
                points += &format!(", network on {} points", self.network_points);
            }
            if self.template_points != default_template_points() {
                points += &format!(", {}-point template", self.template_points);
            }
            if self.view_check {
                points += ", view check";
            }
            if self.icp_iterations == 0 {
                format!("{precision} K={}{points}, scored, no ICP", self.hypotheses)
            } else {
                format!(
                    "{precision} K={}{points} + device ICP{metric}",
                    self.hypotheses
                )
            }
        } else {
            precision
        };
        let refine = if self.refine_icp && self.kind != MethodKind::Icp {
            " + ICP"
        } else {
            ""
        };
        format!("{base}{precision}{refine}")
    }
}

/// What one registration produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Pose mapping the source onto the template.
    pub pose: Pose,
    /// Passes, steps or iterations run (of the first stage when refined).
    pub iterations: usize,
    /// The network path that ran (network methods).
    pub precision: Option<Precision>,
    /// Wall time of the whole registration, seconds.
    pub seconds: f64,
    /// The pose after each step, when the method records it (PointNetLK,
    /// ICP without a network stage).
    pub trajectory: Option<Vec<Pose>>,
    /// The device pipeline's residual and flags.
    pub check: Option<pcrnet_core::Registration>,
    /// The pose checked in feature space: the int8 device pipeline's
    /// ([`pcrnet_core::Int8Model::feature_distance`]) or PointNetLK's own
    /// residual at its final pose; not timed.
    pub feature_distance: Option<f64>,
    /// The source's shape does not determine a pose (every point in one
    /// place, or on one line), judged for every method by the device's
    /// rule ([`pcrnet_core::refine::degeneracy`]) in the template's frame:
    /// the pose is then not to be acted on, whatever the method returned.
    pub degenerate: Option<Degeneracy>,
    /// The check against the single view from its viewpoint
    /// ([`Method::view_check`]): the pose is to be acted on only when
    /// `check`'s `reliable` is set and this passed ([`Outcome::reliable`]).
    pub view: Option<pcrnet_core::scene::Verification>,
}

impl Outcome {
    /// The device pipeline's verdict: its registration's, and with a view
    /// check that too; `None` for methods without one.
    pub fn reliable(&self) -> Option<bool> {
        let c = self.check.as_ref()?;
        Some(c.reliable && self.view.is_none_or(|v| v.passed))
    }
}

/// Why a registration failed.
#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    /// A network method was run without a model blob.
    #[error(
        "--method {0} needs a model: pass --model FILE (the shipped one is models/embedded-default-int8.pcrn; pointnetlk needs an f32 blob such as models/embedded-default-f32.pcrn)"
    )]
    NoModel(MethodKind),
    /// PointNetLK was given an int8 blob.
    #[error(
        "--method pointnetlk needs the f32 blob (its Jacobian is taken on f32 features), such as models/embedded-default-f32.pcrn; this one is int8"
    )]
    NeedsF32,
    /// The network, the blob or the template failed.
    #[error(transparent)]
    Model(#[from] TemplateError),
    /// ICP failed.
    #[error(transparent)]
    Icp(#[from] IcpError),
    /// Host ICP refinement needs the template as a cloud.
    #[error("ICP (and --refine-icp) needs the template as a cloud: give TEMPLATE SOURCE")]
    NoTemplate,
    /// The view check was asked for without the sensor's viewpoint.
    #[error(
        "the view check needs the sensor's viewpoint in the source's frame (--viewpoint X,Y,Z)"
    )]
    NoViewpoint,
}

/// Registers `source` onto `template` with `method` (and the model `blob`
/// for network methods; its kind picks the int8 or f32 path). Without a
/// template, network methods use the blob's own (as a device does); ICP
/// needs one. `viewpoint` is the sensor's position in the source's frame,
/// when the source is a cut single view: what [`Method::view_check`] needs.
pub fn run(
    method: &Method,
    blob: Option<&[u8]>,
    template: Option<&[[f32; 3]]>,
    source: &[[f32; 3]],
    viewpoint: Option<[f32; 3]>,
) -> Result<Outcome, MethodError> {
    let start = Instant::now();
    let mut untimed = std::time::Duration::ZERO;
    let model = || blob.ok_or(MethodError::NoModel(method.kind));
    // One reference for the degeneracy verdict and the bound blob: each
    // takes several milliseconds to build, as long as a network pass.
    // Without the closest-point table: it gives the same results (the
    // device pipeline searches the grid instead) and would take longer to
    // build (about 50 ms at 512 points) than it saves on one pair.
    let reference = template
        .map(|cloud| Reference::with_table(cloud, method.template_points, None))
        .transpose()?;
    let degenerate = source_degeneracy(blob, reference.as_ref(), source)?;
    // The blob with the template bound in place of its own. The network's
    // template feature is taken from the whole cloud (centred on all of
    // it, pooled over the network's default sample of it), so the stored
    // points (`method.template_points`) change only what the device
    // pipeline checks and refines against.
    let bound = |blob| -> Result<Cow<'_, [u8]>, MethodError> {
        Ok(match &reference {
            Some(r) => Cow::Owned(bind_reference(blob, r)?),
            None => Cow::Borrowed(blob),
        })
    };
    let mut out = match method.kind {
        MethodKind::Icp => {
            let config = IcpConfig {
                max_iterations: method.iterations,
                ..IcpConfig::default()
            };
            let r = icp(template.ok_or(MethodError::NoTemplate)?, source, config)?;
            Outcome {
                pose: r.pose,
                iterations: r.iterations,
                precision: None,
                seconds: 0.0,
                trajectory: Some(r.trajectory),
                check: None,
                feature_distance: None,
                degenerate,
                view: None,
            }
        }
        MethodKind::Device => {
            let blob = bound(model()?)?;
            let options = method.device_options();
            let (r, view, precision) = match (method.view_check, viewpoint) {
                (false, _) => {
                    let (r, precision) = pipeline(&blob, None, source, &options)?;
                    (r, None, precision)
                }
                (true, None) => return Err(MethodError::NoViewpoint),
                (true, Some(v)) => {
                    let (seen, precision) = pipeline_viewed(&blob, source, v, &options)?;
                    (seen.registration, Some(seen.view), precision)
                }
            };
            let checking = Instant::now();
            let feature_distance = feature_distance(&blob, source, &r.pose);
            untimed = checking.elapsed();
            Outcome {
                pose: r.pose,
                iterations: r.passes,
                precision: Some(precision),
                seconds: 0.0,
                trajectory: None,
                check: Some(r),
                feature_distance,
                degenerate,
                view,
            }
        }
        MethodKind::Pointnetlk => {
            let r = register_pointnetlk(model()?, template, source, method.iterations).map_err(
                |e| match e {
                    TemplateError::Core(pcrnet_core::Error::WrongKind { found: 0, .. }) => {
                        MethodError::NeedsF32
                    }
                    e => e.into(),
                },
            )?;
            untimed = std::time::Duration::from_secs_f64(r.check_seconds);
            Outcome {
                pose: r.pose,
                iterations: r.iterations,
                precision: Some(Precision::F32),
                seconds: 0.0,
                trajectory: Some(r.trajectory),
                check: None,
                feature_distance: Some(r.feature_distance),
                degenerate,
                view: None,
            }
        }
        MethodKind::Pcrnet | MethodKind::Ipcrnet => {
            let passes = match method.kind {
                MethodKind::Pcrnet => 1,
                _ => method.iterations,
            };
            let r = network(&bound(model()?)?, None, source, passes, method.tolerance)?;
            Outcome {
                pose: r.pose,
                iterations: r.passes,
                precision: Some(r.precision),
                seconds: 0.0,
                trajectory: None,
                check: None,
                feature_distance: None,
                degenerate,
                view: None,
            }
        }
    };
    if method.refine_icp && method.kind != MethodKind::Icp {
        let moved: Vec<[f32; 3]> = source
            .iter()
            .map(|&p| out.pose.transform_point(p))
            .collect();
        let template = template.ok_or(MethodError::NoTemplate)?;
        let r = icp(template, &moved, IcpConfig::default())?;
        out.pose = out.pose.then(&r.pose);
        out.trajectory = None;
    }
    out.seconds = start.elapsed().saturating_sub(untimed).as_secs_f64();
    Ok(out)
}

/// The feature-space check of an int8 blob's pose (`None` for an f32 blob
/// or when it fails: it is a measurement beside the registration).
fn feature_distance(blob: &[u8], source: &[[f32; 3]], pose: &Pose) -> Option<f64> {
    let model = pcrnet_core::Int8Model::from_bytes(blob).ok()?;
    let mut scratch = vec![0i8; model.host_scratch_len()];
    model
        .feature_distance(source, pose, &mut scratch)
        .ok()
        .map(f64::from)
}

/// What is wrong with running a blob trained for `trained` passes as
/// `kind` with `passes` passes (`None`: the method's default), or `None`
/// if nothing: iterating a one-pass PCRNet (it was never trained to
/// correct its own output, and diverges on unseen shapes: 73 deg mean in
/// issue 10), one pass of an i-PCRNet (it stops short of its accuracy), or
/// a pass count other than the one the blob was trained for.
pub fn mode_mismatch(kind: MethodKind, trained: usize, passes: Option<usize>) -> Option<String> {
    let mode = if trained == 1 {
        "one pass (PCRNet)".to_string()
    } else {
        format!("{trained} passes (i-PCRNet)")
    };
    match (kind, passes) {
        (MethodKind::Ipcrnet, _) if trained == 1 => Some(format!(
            "this model was trained for {mode}; --method ipcrnet iterates it anyway, which can diverge (use --method pcrnet or device)"
        )),
        (MethodKind::Pcrnet, _) if trained > 1 => Some(format!(
            "this model was trained for {mode}; --method pcrnet runs one and stops short of its accuracy (use --method ipcrnet or device)"
        )),
        (MethodKind::Ipcrnet | MethodKind::Device, Some(n)) if n != trained => Some(format!(
            "this model was trained for {mode}; --iterations {n} runs it for {n}"
        )),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcrnet_train::shapes::{Shape, sample};

    #[test]
    fn names_and_defaults() {
        let m = Method::new(MethodKind::Ipcrnet);
        assert_eq!(m.iterations, 20);
        assert_eq!(
            m.then_icp().name(Some(Precision::Int8)),
            "i-PCRNet int8 + ICP"
        );
        assert_eq!(Method::new(MethodKind::Icp).iterations, 100);
        assert_eq!(Method::new(MethodKind::Icp).name(None), "ICP");
        assert!(!Method::new(MethodKind::Icp).needs_model());
    }

    #[test]
    fn networks_need_a_model_and_icp_refines() {
        let t = sample(Shape::Ell, 200, 1);
        assert!(matches!(
            run(&Method::new(MethodKind::Pcrnet), None, Some(&t), &t, None),
            Err(MethodError::NoModel(MethodKind::Pcrnet))
        ));
        // ICP on a small known offset: exact, with a trajectory.
        let shifted: Vec<[f32; 3]> = t.iter().map(|p| [p[0] + 0.02, p[1], p[2]]).collect();
        let r = run(
            &Method::new(MethodKind::Icp),
            None,
            Some(&t),
            &shifted,
            None,
        )
        .unwrap();
        assert!((r.pose.translation[0] + 0.02).abs() < 1e-4, "{:?}", r.pose);
        assert_eq!(r.trajectory.map(|v| v.len()), Some(r.iterations));
        assert!(r.seconds > 0.0);
    }

    /// `run` builds the template's reference once, for the degeneracy
    /// verdict and the bound blob: its poses are those of binding the
    /// template inside `network` and `pipeline`, and the stored point count
    /// changes nothing for the network methods, on an int8 blob whose head
    /// is biased to the identity (so that the device ICP refines against
    /// the stored points) and on an f32 one.
    #[test]
    fn one_reference_gives_the_bound_poses() {
        use crate::register::Bound;
        use crate::register::tests::identity_biased;
        use pcrnet_train::shapes::random_transform;
        use pcrnet_train::{F32Params, TrainedFor};
        let template = sample(Shape::Ell, 600, 3);
        let source = random_transform(&sample(Shape::Ell, 400, 11), 8.0, 0.05, 4);
        let reference = Reference::new(&template, 64).unwrap();
        let int8_blob = identity_biased(&reference, &template);
        let params = F32Params::init(pcrnet_core::Arch::new(&[16, 32], &[32]).unwrap(), 5);
        let f32_blob = params
            .to_f32_blob(&reference, TrainedFor::pcrnet(true))
            .unwrap();
        let mut refined = 0;
        for blob in [&int8_blob, &f32_blob] {
            let want = network(blob, Some(&template), &source, 1, 0.0)
                .unwrap()
                .pose;
            for stored in [DEFAULT_TEMPLATE_POINTS, 100] {
                let mut m = Method::new(MethodKind::Pcrnet);
                m.template_points = stored;
                let got = run(&m, Some(blob), Some(&template), &source, None).unwrap();
                assert_eq!(got.pose, want, "PCRNet, {stored} stored points");
                m.kind = MethodKind::Device;
                let got = run(&m, Some(blob), Some(&template), &source, None).unwrap();
                let bound = Bound {
                    cloud: &template,
                    stored,
                };
                let options = m.device_options();
                let (want, _) = pipeline(blob, Some(bound), &source, &options).unwrap();
                assert_eq!(got.pose, want.pose, "device, {stored} stored points");
                refined += usize::from(want.icp_iterations > 0);
            }
        }
        // The int8 blob's poses came from ICP on the stored points.
        assert!(refined >= 2, "{refined} device runs refined");
    }

    /// Issue 10, item 9, as a kind: every mismatch between the mode a blob
    /// was trained for and the method run is named, with what to use.
    #[test]
    fn mode_mismatches_are_named() {
        use MethodKind::{Device, Icp, Ipcrnet, Pcrnet};
        let said = |kind, trained, passes| mode_mismatch(kind, trained, passes).unwrap_or_default();
        assert!(said(Ipcrnet, 1, None).contains("trained for one pass (PCRNet)"));
        assert!(said(Ipcrnet, 1, None).contains("--method pcrnet or device"));
        assert!(said(Pcrnet, 8, None).contains("trained for 8 passes (i-PCRNet)"));
        assert!(said(Pcrnet, 8, None).contains("--method ipcrnet or device"));
        assert!(said(Device, 1, Some(5)).contains("--iterations 5"));
        assert!(said(Ipcrnet, 8, Some(3)).contains("--iterations 3"));
        for ok in [
            mode_mismatch(Pcrnet, 1, None),
            mode_mismatch(Ipcrnet, 8, None),
            mode_mismatch(Ipcrnet, 8, Some(8)),
            mode_mismatch(Device, 8, None),
            mode_mismatch(Device, 1, Some(1)),
            mode_mismatch(Icp, 1, Some(30)),
        ] {
            assert_eq!(ok, None);
        }
    }
}
