//! Post-training quantization of [`F32Params`] into `pcrnet-core`'s int8 blob.
//!
//! # Rule
//! - **Weights**: symmetric per output channel, `s_w[o] = max_i |w[o][i]| / 127`,
//!   `q = round(w / s_w[o])` in `[-127, 127]`.
//! - **Activations**: every encoder and hidden head layer is followed by
//!   ReLU, so its range is `[0, m]` with `m` the **largest value observed**
//!   at that layer over the calibration set (every point of every
//!   calibration cloud for the encoder; every calibration pair for the
//!   head). Scale `m / 255`, zero point -128, so the full int8 range covers
//!   `activation_headroom x [0, m]` (headroom 1.25 by default). The max
//!   rather than a percentile, and a headroom on top, because the max-pool
//!   keeps exactly the extreme values and clipping them biases the feature.
//!   Measured on a random 32-64-128-256 encoder, 16 calibration clouds:
//!   relative feature error 5.9% with headroom 1.0 (clipping), 0.8% with
//!   1.25, 1.0% with 1.5; with 128 calibration clouds and headroom 1.0, 0.9%.
//! - **Input**: int16 with zero point 0 and scale
//!   `headroom * max|coordinate| / 32767` over the calibration clouds
//!   (headroom 2 by default: sensor clouds may be larger than training ones;
//!   at step ~1e-4 the input rounding stays far below other errors).
//! - **Bias**: `round(b / (s_x s_w[o]))`, input zero point folded in,
//!   clamped so the accumulator provably stays inside i32.
//! - **Requantization**: `s_x s_w[o] / s_y` as Q31 multiplier and shift
//!   ([`pcrnet_core::fixed::quantize_multiplier`]).
//! - **Output layer**: not requantized; its per-output scale `s_x s_w[o]`
//!   turns the i32 accumulators into reals.
//! - **Template feature**: computed by the int8 encoder itself (`pcrnet-core`),
//!   so it is exactly what the device would compute.

use pcrnet_core::Frame;
use pcrnet_core::fixed::quantize_multiplier;
use pcrnet_core::float::{Layer, dense};
use pcrnet_core::format::{Int8Layer, Int8Output, Int8Payload};
use pcrnet_core::pose::{Centring, Rigid};

use crate::net::{F32Params, TrainedFor, le_bytes};
use crate::template::{Reference, TemplateError, int8_blob};

/// Why quantization failed.
#[derive(Debug, thiserror::Error)]
pub enum QuantizeError {
    /// No calibration cloud, or one without points.
    #[error("calibration needs at least one non-empty cloud")]
    NoCalibrationData,
    /// A calibration coordinate is NaN or infinite.
    #[error("calibration cloud {cloud} has a non-finite coordinate")]
    NonFinite {
        /// Index of the cloud.
        cloud: usize,
    },
    /// A scale could not be expressed as a Q31 multiplier.
    #[error("layer {layer}: requantization scale {scale} out of range")]
    Scale {
        /// Layer index (encoder then head).
        layer: usize,
        /// The real scale.
        scale: f64,
    },
    /// `pcrnet-core` rejected the result.
    #[error(transparent)]
    Core(#[from] pcrnet_core::Error),
    /// The template could not be recorded.
    #[error(transparent)]
    Template(#[from] TemplateError),
}

/// How the activation and input ranges are chosen (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationRule {
    /// Input range = `input_headroom x` the largest calibration coordinate.
    pub input_headroom: f32,
    /// Activation range = `activation_headroom x` the largest value observed.
    pub activation_headroom: f32,
}

impl Default for CalibrationRule {
    fn default() -> Self {
        CalibrationRule {
            input_headroom: 2.0,
            activation_headroom: 1.25,
        }
    }
}

/// Largest value seen at every layer's output, and the largest |coordinate|.
#[derive(Debug, Clone, PartialEq)]
pub struct Ranges {
    /// Per encoder layer.
    pub encoder: Vec<f32>,
    /// Per hidden head layer.
    pub head: Vec<f32>,
    /// Largest |coordinate| of the calibration clouds.
    pub input: f32,
}

fn layer<'a>(w: &'a [f32], b: &'a [f32]) -> Layer<&'a [f32]> {
    Layer {
        weights: w,
        bias: b,
    }
}

/// Runs the f32 network (pcrnet-core's `dense`) over the calibration clouds,
/// recording the largest activation of every layer.
pub fn calibrate(
    params: &F32Params,
    template: &[[f32; 3]],
    clouds: &[Vec<[f32; 3]>],
) -> Result<Ranges, QuantizeError> {
    if clouds.is_empty() || clouds.iter().any(|c| c.is_empty()) {
        return Err(QuantizeError::NoCalibrationData);
    }
    let arch = &params.arch;
    let n_enc = arch.encoder.len();
    let template_feature = params.encode(template)?;
    let mut r = Ranges {
        encoder: vec![0.0; n_enc],
        head: vec![0.0; arch.head.len()],
        input: 0.0,
    };
    for (ci, cloud) in clouds.iter().enumerate() {
        let mut feature = vec![f32::NEG_INFINITY; arch.feature_dim()];
        for p in cloud {
            if p.iter().any(|x| !x.is_finite()) {
                return Err(QuantizeError::NonFinite { cloud: ci });
            }
            r.input = p.iter().fold(r.input, |m, x| m.max(x.abs()));
            let mut x = p.to_vec();
            for (l, ((w, b), s)) in params.layers[..n_enc]
                .iter()
                .zip(arch.encoder_layers())
                .enumerate()
            {
                let mut y = vec![0.0; s.outputs];
                dense(&layer(w, b), &x, s.outputs, true, |o, v| y[o] = v);
                r.encoder[l] = y.iter().fold(r.encoder[l], |m, &v| m.max(v));
                x = y;
            }
            for (f, v) in feature.iter_mut().zip(&x) {
                *f = f.max(*v);
            }
        }
        let mut x: Vec<f32> = template_feature.iter().chain(&feature).copied().collect();
        for (l, ((w, b), s)) in params.layers[n_enc..]
            .iter()
            .zip(arch.head_layers())
            .take(arch.head.len())
            .enumerate()
        {
            let mut y = vec![0.0; s.outputs];
            dense(&layer(w, b), &x, s.outputs, true, |o, v| y[o] = v);
            r.head[l] = y.iter().fold(r.head[l], |m, &v| m.max(v));
            x = y;
        }
    }
    Ok(r)
}

/// Owned bytes of one quantized layer.
#[derive(Default)]
struct QLayer {
    out_scale: f32,
    weights: Vec<u8>,
    bias: Vec<u8>,
    multiplier: Vec<u8>,
    shift: Vec<u8>,
    /// Per-output `s_x s_w[o]` (used by the output layer).
    acc_scale: Vec<f32>,
}

impl QLayer {
    fn view(&self) -> Int8Layer<'_> {
        Int8Layer {
            out_scale: self.out_scale,
            out_zero_point: -128,
            weights: &self.weights,
            bias: &self.bias,
            multiplier: &self.multiplier,
            shift: &self.shift,
        }
    }
}

/// Quantizes one layer. `s_x`, `z_x`, `x_max` describe its input
/// (`x_max`: largest |x - z_x|), `s_y` its output scale (ignored when `requant` is false).
#[allow(clippy::too_many_arguments)]
fn quantize_layer(
    index: usize,
    w: &[f32],
    b: &[f32],
    inputs: usize,
    s_x: f64,
    z_x: i64,
    x_max: i64,
    s_y: f64,
) -> Result<QLayer, QuantizeError> {
    let outputs = b.len();
    let mut q = QLayer {
        out_scale: s_y as f32,
        weights: Vec::with_capacity(w.len()),
        bias: Vec::new(),
        multiplier: Vec::new(),
        shift: Vec::new(),
        acc_scale: Vec::new(),
    };
    for o in 0..outputs {
        let row = &w[o * inputs..(o + 1) * inputs];
        let absmax = row.iter().fold(0f32, |m, v| m.max(v.abs()));
        let s_w = if absmax > 0.0 {
            absmax as f64 / 127.0
        } else {
            1.0
        };
        let qrow: Vec<i64> = row
            .iter()
            .map(|&v| (v as f64 / s_w).round().clamp(-127.0, 127.0) as i64)
            .collect();
        let sum: i64 = qrow.iter().sum();
        let abs_sum: i64 = qrow.iter().map(|v| v.abs()).sum();
        let acc_scale = s_x * s_w;
        let limit = i32::MAX as i64 - abs_sum * x_max;
        let bias = ((b[o] as f64 / acc_scale).round() as i64 - z_x * sum).clamp(-limit, limit);
        q.weights.extend(qrow.iter().map(|&v| v as i8 as u8));
        q.bias.extend_from_slice(&(bias as i32).to_le_bytes());
        q.acc_scale.push(acc_scale as f32);
        let real = acc_scale / s_y;
        let (m, s) = quantize_multiplier(real).ok_or(QuantizeError::Scale {
            layer: index,
            scale: real,
        })?;
        q.multiplier.extend_from_slice(&m.to_le_bytes());
        q.shift.push(s as u8);
    }
    Ok(q)
}

/// Quantizes `params` with calibration clouds (model frame) and returns the
/// int8 blob recording `reference` (frame, template points, and the
/// template feature computed by the int8 encoder).
/// With `centre_source` (a network trained on centred sources) the blob
/// says so, and the calibration clouds are centred as the device will
/// centre its sources (`pcrnet_core::pose::centring`).
pub fn quantize(
    params: &F32Params,
    reference: &Reference,
    calibration: &[Vec<[f32; 3]>],
    rule: CalibrationRule,
    trained: TrainedFor,
) -> Result<Vec<u8>, QuantizeError> {
    let centre_source = trained.centre_source;
    let centred: Vec<Vec<[f32; 3]>>;
    let calibration = if centre_source {
        centred = calibration
            .iter()
            .map(|c| {
                // Clean shapes: the device's robust centroid is their centroid.
                let every_point = Centring::Centroid {
                    radius: f32::INFINITY,
                };
                let moved = Rigid::from(&pcrnet_core::pose::centring(
                    c,
                    every_point,
                    &Frame::IDENTITY,
                )?);
                Ok(c.iter().map(|&p| moved.apply(p)).collect())
            })
            .collect::<Result<_, pcrnet_core::Error>>()?;
        &centred[..]
    } else {
        calibration
    };
    let params = &params.for_blob(trained);
    let ranges = calibrate(params, &reference.normalised(), calibration)?;
    let arch = &params.arch;
    let n_enc = arch.encoder.len();
    let act_scale = |m: f32| (m.max(1e-6) * rule.activation_headroom) as f64 / 255.0;
    let input_scale = (ranges.input.max(1e-6) * rule.input_headroom) / 32767.0;

    let mut layers = Vec::new();
    let (mut s_x, mut z_x, mut x_max) = (input_scale as f64, 0i64, 32767i64);
    for (l, s) in arch.encoder_layers().enumerate() {
        let (w, b) = &params.layers[l];
        let s_y = act_scale(ranges.encoder[l]);
        layers.push(quantize_layer(l, w, b, s.inputs, s_x, z_x, x_max, s_y)?);
        (s_x, z_x, x_max) = (s_y, -128, 255);
    }
    // A PointNetLK blob has no head: the encoder's layers are all there are.
    let head_layers = params.layers.len() - n_enc;
    for (h, s) in arch.head_layers().enumerate().take(head_layers) {
        let l = n_enc + h;
        let (w, b) = &params.layers[l];
        // The output layer is not requantized: pass its own accumulator scale.
        let s_y = if s.relu {
            act_scale(ranges.head[h])
        } else {
            1.0
        };
        layers.push(quantize_layer(l, w, b, s.inputs, s_x, z_x, x_max, s_y)?);
        (s_x, z_x, x_max) = (s_y, -128, 255);
    }
    // Without a head the output layer is empty (the blob's mark of one).
    let output = match head_layers {
        0 => QLayer::default(),
        _ => layers.pop().unwrap_or_default(),
    };
    let out_scale = le_bytes(&output.acc_scale);

    let payload = Int8Payload {
        arch: arch.clone(),
        centre_source,
        passes: trained.passes,
        frame: reference.frame,
        template: reference.cloud(),
        input_scale,
        encoder: layers[..n_enc].iter().map(QLayer::view).collect(),
        head: layers[n_enc..].iter().map(QLayer::view).collect(),
        output: Int8Output {
            weights: &output.weights,
            bias: &output.bias,
            scale: &out_scale,
        },
        template_feature: &[],
    };
    Ok(int8_blob(&payload, reference, trained.has_lk_solver())?)
}
