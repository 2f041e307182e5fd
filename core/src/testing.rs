//! Seeded random models for tests, examples and the QEMU harness.
//!
//! Not part of the stable API. Everything here is `no_std` and allocation
//! free: the caller lends an arena for the weights and an output buffer for
//! the blob, so the same generator runs on the host and on a device.

use crate::arch::{Arch, MAX_LAYERS, POSE_DIM};
use crate::error::{Error, Result};
use crate::fixed::quantize_multiplier;
use crate::format::{
    F32Layer, F32Payload, Frame, Int8Layer, Int8Output, Int8Payload, LkSolver, ModelKind,
    TemplateCloud, Trailer, decode_model, write_blob,
};
use crate::int8::Int8Model;
use crate::lk::TWIST_DIM;
use crate::template;

pub use crate::random::SplitMix64;

pub mod scene;

/// Carves `n` bytes off the front of an arena.
fn take<'a>(arena: &mut &'a mut [u8], n: usize) -> Result<&'a mut [u8]> {
    let available = arena.len();
    if n > available {
        return Err(Error::BufferTooSmall {
            needed: n,
            available,
        });
    }
    let (head, tail) = core::mem::take(arena).split_at_mut(n);
    *arena = tail;
    Ok(head)
}

/// Input scale of the random int8 models: coordinates up to +-4.
pub const RANDOM_INPUT_SCALE: f32 = 4.0 / 32767.0;

/// Fills an int8 layer with random weights and parameters that keep the
/// activations spread over the int8 range. `x_std` is the typical magnitude
/// of `x - z_x` at the layer's input, `in_zp` the input zero point.
fn random_int8_layer<'a>(
    rng: &mut SplitMix64,
    arena: &mut &'a mut [u8],
    inputs: usize,
    outputs: usize,
    in_zp: i32,
    x_std: f32,
) -> Result<Int8Layer<'a>> {
    let weights = take(arena, inputs * outputs)?;
    let bias = take(arena, 4 * outputs)?;
    let multiplier = take(arena, 4 * outputs)?;
    let shift = take(arena, outputs)?;
    let acc_std = libm::sqrtf(inputs as f32) * 73.0 * x_std;
    for o in 0..outputs {
        let row = &mut weights[o * inputs..(o + 1) * inputs];
        let mut sum = 0i32;
        for w in row.iter_mut() {
            let v = rng.int(-127, 127);
            sum += v;
            *w = v as i8 as u8;
        }
        let b = rng.uniform(-0.5, 0.5) * acc_std;
        let folded = libm::roundf(b) as i32 - in_zp * sum;
        bias[4 * o..4 * o + 4].copy_from_slice(&folded.to_le_bytes());
        let real = rng.uniform(30.0, 60.0) / acc_std;
        let (m, s) = quantize_multiplier(real as f64).ok_or(Error::InvalidParameter {
            what: "random multiplier",
        })?;
        multiplier[4 * o..4 * o + 4].copy_from_slice(&m.to_le_bytes());
        shift[o] = s as u8;
    }
    Ok(Int8Layer {
        out_scale: 0.05,
        out_zero_point: -128,
        weights,
        bias,
        multiplier,
        shift,
    })
}

static ZEROS: [u8; 4096] = [0; 4096];

/// A random point cloud in `[-1, 1)^3`.
pub fn random_cloud<const N: usize>(rng: &mut SplitMix64) -> [[f32; 3]; N] {
    let mut pts = [[0f32; 3]; N];
    for p in pts.iter_mut() {
        for x in p.iter_mut() {
            *x = rng.uniform(-1.0, 1.0);
        }
    }
    pts
}

/// Writes a random int8 model blob into `out` (weights generated into
/// `arena`). Its template feature is the int8 encoding of a random 64-point
/// cloud. Feature size must be at most 4096. The model does not centre sources.
pub fn random_int8_blob_into<'o>(
    seed: u64,
    encoder: &[u16],
    head: &[u16],
    arena: &mut [u8],
    out: &'o mut [u8],
) -> Result<&'o [u8]> {
    random_int8_blob_with(seed, encoder, head, false, Frame::IDENTITY, arena, out)
}

/// Model units per int16 step of the random models' template points.
pub const RANDOM_TEMPLATE_STEP: f32 = 1.0 / 16384.0;

/// The template cloud of a random model: `cloud` (model frame) on the
/// int16 grid with radial normals, a 4^3 grid, and half turns about the
/// three axes.
fn random_template<'o>(cloud: &[[f32; 3]], arena: &mut &'o mut [u8]) -> Result<TemplateCloud<'o>> {
    let mut q = [[0i16; 3]; 64];
    let mut n = [[0i8; 3]; 64];
    let q = q.get_mut(..cloud.len()).ok_or(Error::InvalidParameter {
        what: "random template wider than 64 points",
    })?;
    for ((q, n), p) in q.iter_mut().zip(n.iter_mut()).zip(cloud) {
        *q = p.map(|x| libm::roundf(x / RANDOM_TEMPLATE_STEP) as i16);
        let len = libm::sqrtf(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        *n = if len > 1e-3 {
            p.map(|x| libm::roundf(127.0 * x / len) as i8)
        } else {
            [127, 0, 0]
        };
    }
    let (np, nn, nc) = template::build_len(q.len(), 4);
    let out = template::BuildOut {
        points: take(arena, np)?,
        normals: take(arena, nn)?,
        cells: take(arena, nc)?,
    };
    let turns = [
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    template::build(q, &n[..q.len()], RANDOM_TEMPLATE_STEP, 4, &turns, out)
}

/// As [`random_int8_blob_into`], choosing whether the model centres sources
/// and its frame (user units -> model frame).
pub fn random_int8_blob_with<'o>(
    seed: u64,
    encoder: &[u16],
    head: &[u16],
    centre_source: bool,
    frame: Frame,
    arena: &mut [u8],
    out: &'o mut [u8],
) -> Result<&'o [u8]> {
    let arch = Arch::new(encoder, head)?;
    let f = arch.feature_dim();
    if f > ZEROS.len() {
        return Err(Error::InvalidParameter {
            what: "random model feature wider than 4096",
        });
    }
    let mut rng = SplitMix64(seed);
    let mut arena = arena;
    let template = take(&mut arena, f)?;
    let mut enc = heapless::Vec::<Int8Layer<'_>, MAX_LAYERS>::new();
    for (i, s) in arch.encoder_layers().enumerate() {
        let (zp, x_std) = if i == 0 {
            (0, 0.5 / RANDOM_INPUT_SCALE)
        } else {
            (-128, 40.0)
        };
        let layer = random_int8_layer(&mut rng, &mut arena, s.inputs, s.outputs, zp, x_std)?;
        let _ = enc.push(layer);
    }
    let mut hd = heapless::Vec::<Int8Layer<'_>, MAX_LAYERS>::new();
    let mut last_in = 2 * f;
    for s in arch.head_layers().filter(|s| s.relu) {
        let layer = random_int8_layer(&mut rng, &mut arena, s.inputs, s.outputs, -128, 40.0)?;
        let _ = hd.push(layer);
        last_in = s.outputs;
    }
    let out_layer = random_int8_layer(&mut rng, &mut arena, last_in, POSE_DIM, -128, 40.0)?;
    let scale = take(&mut arena, 4 * POSE_DIM)?;
    for c in scale.chunks_exact_mut(4) {
        c.copy_from_slice(&rng.uniform(1e-5, 1e-4).to_le_bytes());
    }
    let cloud: [[f32; 3]; 64] = random_cloud(&mut rng);
    let template_cloud = random_template(&cloud, &mut arena)?;
    let mut payload = Int8Payload {
        arch,
        centre_source,
        passes: 1,
        frame,
        template: template_cloud,
        input_scale: RANDOM_INPUT_SCALE,
        encoder: enc,
        head: hd,
        output: Int8Output {
            weights: out_layer.weights,
            bias: out_layer.bias,
            scale,
        },
        template_feature: &ZEROS[..f],
    };
    // Encode the template with the model itself, as the exporter does: in
    // user units, which the model moves into its frame.
    let user = cloud.map(|p| [0, 1, 2].map(|k| p[k] / frame.scale + frame.centre[k]));
    let mut buf = [0i8; 3 * 4096];
    let model = Int8Model::from_payload(payload.clone(), Trailer::default())?;
    let needed = model.scratch_len(1);
    let available = buf.len();
    let scratch = buf
        .get_mut(..needed)
        .ok_or(Error::BufferTooSmall { needed, available })?;
    let feature = model.encode_tiled(&user, 1, scratch)?;
    for (t, &v) in template.iter_mut().zip(feature) {
        *t = v as u8;
    }
    payload.template_feature = template;
    let n = write_blob(ModelKind::Int8, &payload, &Trailer::default(), out)?;
    Ok(&out[..n])
}

/// Bound of a random LK solver's entries times the feature width `F`: the
/// entries are uniform in `+-RANDOM_LK_SPREAD / F`, so that a twist
/// component (a sum of `F` int8 feature differences of some tens) stays a
/// fraction of a radian or model unit, steps moderate.
pub const RANDOM_LK_SPREAD: f32 = 0.125;

/// Writes the int8 model `blob` again with a random PointNetLK solver
/// ([`LkSolver`], entries uniform in `+-RANDOM_LK_SPREAD / F`; no
/// Jacobian behind them, so its steps check that devices agree, not that
/// LK converges) and, if `headless`, without its head (no hidden head
/// layer and an empty output layer: the shape of a model trained as
/// PointNetLK). The payload is otherwise unchanged and the closest-point
/// table kept; the solver's rows go into `arena`. The result is checked
/// as `Int8Model::from_bytes` checks a blob.
pub fn with_random_lk_solver<'o>(
    blob: &[u8],
    seed: u64,
    headless: bool,
    arena: &mut [u8],
    out: &'o mut [u8],
) -> Result<&'o [u8]> {
    let (mut payload, trailer) = decode_model::<Int8Payload<'_>>(blob, ModelKind::Int8)?;
    if headless {
        payload.arch.head.clear();
        payload.head.clear();
        payload.output = Int8Output {
            weights: &[],
            bias: &[],
            scale: &[],
        };
    }
    let f = payload.arch.feature_dim();
    let mut arena = arena;
    let rows = take(&mut arena, 4 * TWIST_DIM * f)?;
    let bound = RANDOM_LK_SPREAD / f as f32;
    let mut rng = SplitMix64(seed);
    for c in rows.chunks_exact_mut(4) {
        c.copy_from_slice(&rng.uniform(-bound, bound).to_le_bytes());
    }
    let trailer = Trailer {
        table: trailer.table,
        // No finite differences or damping made these rows.
        lk: Some(LkSolver {
            jacobian_step: 0.0,
            central: false,
            damping: 0.0,
            rows,
        }),
        ..trailer
    };
    Int8Model::from_payload(payload.clone(), trailer)?;
    let n = write_blob(ModelKind::Int8, &payload, &trailer, out)?;
    Ok(&out[..n])
}

/// Writes a random f32 model blob (He-style uniform weights) into `out`,
/// with its template feature the f32 encoding of a random 64-point cloud.
pub fn random_f32_blob_into<'o>(
    seed: u64,
    encoder: &[u16],
    head: &[u16],
    arena: &mut [u8],
    out: &'o mut [u8],
) -> Result<&'o [u8]> {
    let arch = Arch::new(encoder, head)?;
    let f = arch.feature_dim();
    let mut rng = SplitMix64(seed);
    let mut arena = arena;
    let mut layers = heapless::Vec::<F32Layer<'_>, { 2 * MAX_LAYERS + 1 }>::new();
    for s in arch.encoder_layers().chain(arch.head_layers()) {
        let w = take(&mut arena, 4 * s.inputs * s.outputs)?;
        let b = take(&mut arena, 4 * s.outputs)?;
        let bound = libm::sqrtf(6.0 / s.inputs as f32);
        for c in w.chunks_exact_mut(4) {
            c.copy_from_slice(&rng.uniform(-bound, bound).to_le_bytes());
        }
        for c in b.chunks_exact_mut(4) {
            c.copy_from_slice(&rng.uniform(-0.1, 0.1).to_le_bytes());
        }
        let _ = layers.push(F32Layer {
            weights: w,
            bias: b,
        });
    }
    let template = take(&mut arena, 4 * f)?;
    let zeros = take(&mut arena, 4 * f)?;
    zeros.fill(0);
    let cloud: [[f32; 3]; 64] = random_cloud(&mut rng);
    let template_cloud = random_template(&cloud, &mut arena)?;
    let mut payload = F32Payload {
        arch,
        centre_source: false,
        passes: 1,
        frame: Frame::IDENTITY,
        template: template_cloud,
        layers,
        template_feature: zeros,
    };
    let model = crate::F32Model::from_payload(payload.clone(), Trailer::default())?;
    let mut scratch = [0f32; 3 * 4096];
    let needed = model.scratch_len();
    let available = scratch.len();
    let scratch = scratch
        .get_mut(..needed)
        .ok_or(Error::BufferTooSmall { needed, available })?;
    let feature = model.network().encode(&cloud, scratch)?;
    for (c, &v) in template.chunks_exact_mut(4).zip(feature) {
        c.copy_from_slice(&v.to_le_bytes());
    }
    payload.template_feature = template;
    let n = write_blob(ModelKind::F32, &payload, &Trailer::default(), out)?;
    Ok(&out[..n])
}

/// Writes `a` as two words, the free axis then the turn, each `none` or its
/// f32 fields as hex bits joined by `:` (axis: direction, point, stiffness;
/// turn: the motion's quaternion and translation, degrees, relative plane
/// residual), so the harness compares device and host bit for bit.
pub fn describe_ambiguity(
    a: &crate::ambiguity::Ambiguity,
    out: &mut impl core::fmt::Write,
) -> core::fmt::Result {
    fn words(out: &mut impl core::fmt::Write, values: &[f32]) -> core::fmt::Result {
        for (i, v) in values.iter().enumerate() {
            let sep = if i == 0 { "" } else { ":" };
            write!(out, "{sep}{:08x}", v.to_bits())?;
        }
        Ok(())
    }
    match a.axis {
        Some(x) => {
            let [d0, d1, d2] = x.direction;
            let [p0, p1, p2] = x.point;
            words(out, &[d0, d1, d2, p0, p1, p2, x.stiffness])?;
        }
        None => write!(out, "none")?,
    }
    write!(out, " ")?;
    match a.turn {
        Some(t) => {
            let [w, x, y, z] = t.motion.rotation;
            let [tx, ty, tz] = t.motion.translation;
            words(
                out,
                &[w, x, y, z, tx, ty, tz, t.degrees, t.relative_plane_residual],
            )
        }
        None => write!(out, "none"),
    }
}

/// Pixels a side of the image of the harness's viewed registration
/// (`Int8Model::register_view`): 32, as the host's `register --viewpoint`.
pub const HARNESS_VIEW_SIDE: usize = 32;

/// The viewpoint the QEMU harness registers `cloud` from
/// (`Int8Model::register_view`): three times the cloud's radius (its farthest
/// finite point from their mean, summed in f32 in point order) from that
/// mean along +z, so every point lies in front of it. The mean of nothing
/// is the origin.
pub fn harness_viewpoint(cloud: &[[f32; 3]]) -> [f32; 3] {
    let finite = || cloud.iter().filter(|p| p.iter().all(|v| v.is_finite()));
    let (mut sum, mut n) = ([0f32; 3], 0u32);
    for p in finite() {
        for k in 0..3 {
            sum[k] += p[k];
        }
        n += 1;
    }
    let c = sum.map(|s| s / n.max(1) as f32);
    let mut radius = 0f32;
    for p in finite() {
        let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        radius = radius.max(libm::sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
    }
    [c[0], c[1], c[2] + 3.0 * radius]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::Options;

    /// A headless blob with a random solver loads, registers by LK alone
    /// and refuses a network pass; one with its head keeps it.
    #[test]
    fn random_lk_solvers_load_and_run() {
        let (mut arena, mut out) = (std::vec![0u8; 1 << 20], std::vec![0u8; 1 << 20]);
        let base = random_int8_blob_into(7, &[16, 32, 64], &[64, 32], &mut arena, &mut out)
            .unwrap()
            .to_vec();
        let mut lk_out = std::vec![0u8; 1 << 20];
        let mut scratch = std::vec![0i8; 64 * 1024];
        let cloud: [[f32; 3]; 100] = random_cloud(&mut SplitMix64(3));
        let lk = Options {
            passes: 0,
            lk_iterations: 5,
            hypotheses: 1,
            icp_iterations: 0,
            ..Options::default()
        };
        let headless = with_random_lk_solver(&base, 1, true, &mut arena, &mut lk_out).unwrap();
        let m = Int8Model::from_bytes(headless).unwrap();
        assert!(!m.has_head());
        assert_eq!(m.lk_solver().map(|s| s.features()), Some(64));
        let r = m.register(&cloud, &lk, &mut scratch).unwrap();
        assert_eq!((r.passes, r.lk_iterations), (0, 5));
        assert!(r.pose.is_finite());
        assert_eq!(
            m.register(&cloud, &Options::default(), &mut scratch),
            Err(Error::NoHead)
        );
        let headed = with_random_lk_solver(&base, 1, false, &mut arena, &mut out).unwrap();
        let m = Int8Model::from_bytes(headed).unwrap();
        assert!(m.has_head() && m.lk_solver().is_some());
        let both = Options {
            lk_iterations: 3,
            ..Options::default()
        };
        let r = m.register(&cloud, &both, &mut scratch).unwrap();
        assert_eq!((r.passes, r.lk_iterations), (1, 3));
    }
}
