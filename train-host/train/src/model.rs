//! The batched PCRNet / i-PCRNet forward and backward passes.
//!
//! The network is the one of [`pcrnet_core::Arch`] with the parameters of
//! [`F32Params`]; the batched forward computes the same function as
//! `pcrnet-core`'s f32 path (`F32Params::network`), up to f32 summation
//! order (tested).
//!
//! # i-PCRNet and gradients
//! i-PCRNet runs `iterations` passes: each predicts a pose from (template,
//! current source), moves the source by it and composes it onto the
//! estimate. **Gradients flow through the last pass only**: the first
//! `iterations - 1` passes are treated as data (no gradient), exactly as the
//! original TensorFlow code (`iterative_PCRNet.py`), which runs the first
//! `MAX_LOOPS - 1` predictions in separate session runs, moves the source in
//! numpy, and runs the train op on the last prediction only. This also
//! keeps memory and backward cost equal to one PCRNet step. The template's
//! encoding is computed once and reused by every pass.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::geometry::{
    self, IDENTITY, Mat3, compose, mat_mul, pose_from_raw, pose_from_raw_backward, transpose,
};
use super::loss::{self, LossKind};
use super::ops;
use crate::F32Params;

/// A rigid transform `(R, t)`: `p -> R p + t`.
pub type RigidPose = (Mat3, [f32; 3]);

/// Rows per GEMM chunk of the encoder forward (points of several clouds).
const CHUNK_ROWS: usize = 2048;

/// Single-pass or iterative network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModelKind {
    /// PCRNet: one pass.
    Pcrnet,
    /// i-PCRNet with this many passes (the paper trains with 8).
    Ipcrnet {
        /// Passes per registration.
        iterations: usize,
    },
    /// PointNetLK ([`crate::lk`]): the encoder trained through this many
    /// Lucas-Kanade iterations (the PointNetLK reference trains with 10);
    /// the head is not used.
    PointNetLk {
        /// LK iterations per registration.
        iterations: usize,
    },
}

impl ModelKind {
    /// Number of passes (LK iterations for PointNetLK).
    pub fn iterations(self) -> usize {
        match self {
            ModelKind::Pcrnet => 1,
            ModelKind::Ipcrnet { iterations } | ModelKind::PointNetLk { iterations } => {
                iterations.max(1)
            }
        }
    }
}

/// Saved encoder activations of a batch of clouds.
#[derive(Debug, Clone)]
pub struct EncoderCache {
    clouds: usize,
    n: usize,
    /// Points, `clouds * n x 3`.
    input: Vec<f32>,
    /// Outputs (after ReLU) of every encoder layer but the last (empty when not kept).
    hidden: Vec<Vec<f32>>,
    /// Winning point of every feature channel, `clouds x F`.
    argmax: Vec<u32>,
    /// Global features after ReLU, `clouds x F`.
    pub feature: Vec<f32>,
}

fn n_encoder(params: &F32Params) -> usize {
    params.arch.encoder.len()
}

/// Encodes `clouds` clouds of `n` points (`points`: `clouds * n` xyz
/// triples, flat). With `keep`, the activations are kept for
/// [`encoder_backward`].
pub fn encode(
    params: &F32Params,
    points: &[f32],
    clouds: usize,
    n: usize,
    keep: bool,
) -> EncoderCache {
    let ne = n_encoder(params);
    let widths: Vec<usize> = params.arch.encoder.iter().map(|&w| w as usize).collect();
    let f = widths[ne - 1];
    let per_chunk = (CHUNK_ROWS / n.max(1)).max(1);
    let mut hidden: Vec<Vec<f32>> = if keep {
        widths[..ne - 1]
            .iter()
            .map(|&w| vec![0.0; clouds * n * w])
            .collect()
    } else {
        Vec::new()
    };
    let mut feature = vec![0.0; clouds * f];
    let mut argmax = vec![0u32; clouds * f];
    let mut bufs: Vec<Vec<f32>> = if keep {
        Vec::new()
    } else {
        widths[..ne - 1]
            .iter()
            .map(|&w| vec![0.0; per_chunk.min(clouds) * n * w])
            .collect()
    };
    let mut start = 0;
    while start < clouds {
        let k = per_chunk.min(clouds - start);
        let rows = k * n;
        let pts = &points[start * n * 3..(start + k) * n * 3];
        let store = if keep { &mut hidden } else { &mut bufs };
        let off = |l: usize| if keep { start * n * widths[l] } else { 0 };
        for l in 0..ne - 1 {
            let (before, after) = store.split_at_mut(l);
            let y = &mut after[0][off(l)..off(l) + rows * widths[l]];
            let x: &[f32] = if l == 0 {
                pts
            } else {
                &before[l - 1][off(l - 1)..off(l - 1) + rows * widths[l - 1]]
            };
            let (w, b) = &params.layers[l];
            ops::dense_forward(x, w, b, rows, y);
            ops::relu(y);
        }
        let x: &[f32] = if ne == 1 {
            pts
        } else {
            &store[ne - 2][off(ne - 2)..off(ne - 2) + rows * widths[ne - 2]]
        };
        let (w, b) = &params.layers[ne - 1];
        let (vals, arg) = ops::dense_maxpool_forward(x, w, b, k, n, k);
        feature[start * f..(start + k) * f].copy_from_slice(&vals);
        argmax[start * f..(start + k) * f].copy_from_slice(&arg);
        start += k;
    }
    ops::relu(&mut feature);
    EncoderCache {
        clouds,
        n,
        input: if keep { points.to_vec() } else { Vec::new() },
        hidden,
        argmax,
        feature,
    }
}

/// Backward through the encoder: from the gradient on the global features
/// (`clouds x F`, after ReLU) into `grads`. The last layer's backward only
/// touches the max-pool's winning points.
pub fn encoder_backward(
    params: &F32Params,
    cache: &EncoderCache,
    dfeature: &[f32],
    grads: &mut F32Params,
) {
    let ne = n_encoder(params);
    let widths: Vec<usize> = params.arch.encoder.iter().map(|&w| w as usize).collect();
    let (clouds, n) = (cache.clouds, cache.n);
    let rows = clouds * n;
    assert!(
        cache.hidden.len() == ne - 1 && !cache.input.is_empty(),
        "encoder_backward needs an EncoderCache made with keep = true"
    );
    let mut dpre = dfeature.to_vec();
    ops::relu_backward(&cache.feature, &mut dpre);
    let x_last: &[f32] = if ne == 1 {
        &cache.input
    } else {
        &cache.hidden[ne - 2]
    };
    let mut dx = (ne > 1).then(|| vec![0.0; rows * widths[ne - 2]]);
    {
        let (dw, db) = &mut grads.layers[ne - 1];
        ops::dense_maxpool_backward(
            x_last,
            &params.layers[ne - 1].0,
            &cache.argmax,
            &dpre,
            clouds,
            n,
            dw,
            db,
            dx.as_deref_mut(),
        );
    }
    for l in (0..ne - 1).rev() {
        let mut dy = dx.take().unwrap_or_default();
        ops::relu_backward(&cache.hidden[l], &mut dy);
        let x: &[f32] = if l == 0 {
            &cache.input
        } else {
            &cache.hidden[l - 1]
        };
        let mut next = (l > 0).then(|| vec![0.0; rows * widths[l - 1]]);
        let (dw, db) = &mut grads.layers[l];
        ops::dense_backward(
            x,
            &params.layers[l].0,
            &dy,
            rows,
            dw,
            db,
            next.as_deref_mut(),
        );
        dx = next;
    }
}

/// Saved head activations of a batch.
#[derive(Debug, Clone)]
pub struct HeadCache {
    batch: usize,
    /// Input of every head layer (the first is `[template | source]` features).
    inputs: Vec<Vec<f32>>,
    /// Raw outputs, `batch x 7`.
    pub out: Vec<f32>,
}

/// Runs the head on `batch` (template feature, source feature) pairs.
pub fn head_forward(params: &F32Params, tf: &[f32], sf: &[f32], batch: usize) -> HeadCache {
    let ne = n_encoder(params);
    let f = params.arch.feature_dim();
    let mut x = Vec::with_capacity(batch * 2 * f);
    for i in 0..batch {
        x.extend_from_slice(&tf[i * f..(i + 1) * f]);
        x.extend_from_slice(&sf[i * f..(i + 1) * f]);
    }
    let mut inputs = Vec::new();
    for (li, shape) in params.arch.head_layers().enumerate() {
        let (w, b) = &params.layers[ne + li];
        let mut y = vec![0.0; batch * shape.outputs];
        ops::dense_forward(&x, w, b, batch, &mut y);
        if shape.relu {
            ops::relu(&mut y);
        }
        inputs.push(std::mem::replace(&mut x, y));
    }
    HeadCache {
        batch,
        inputs,
        out: x,
    }
}

/// Backward through the head from the gradient on the raw outputs
/// (`batch x 7`); returns the gradients on the template and source
/// features (before the encoder's ReLU mask).
pub fn head_backward(
    params: &F32Params,
    cache: &HeadCache,
    dout: &[f32],
    grads: &mut F32Params,
) -> (Vec<f32>, Vec<f32>) {
    let ne = n_encoder(params);
    let f = params.arch.feature_dim();
    let b = cache.batch;
    let shapes: Vec<_> = params.arch.head_layers().collect();
    let mut dy = dout.to_vec();
    for li in (0..shapes.len()).rev() {
        let x = &cache.inputs[li];
        let mut dx = vec![0.0; b * shapes[li].inputs];
        let (dw, db) = &mut grads.layers[ne + li];
        ops::dense_backward(x, &params.layers[ne + li].0, &dy, b, dw, db, Some(&mut dx));
        if li > 0 {
            // `x` is the ReLU output of the previous head layer.
            ops::relu_backward(x, &mut dx);
        }
        dy = dx;
    }
    let mut dtf = Vec::with_capacity(b * f);
    let mut dsf = Vec::with_capacity(b * f);
    for row in dy.chunks_exact(2 * f) {
        dtf.extend_from_slice(&row[..f]);
        dsf.extend_from_slice(&row[f..]);
    }
    (dtf, dsf)
}

/// Parameters of the same shape as `params`, all zero (a gradient buffer).
pub fn zeros_like(params: &F32Params) -> F32Params {
    F32Params {
        arch: params.arch.clone(),
        layers: params
            .layers
            .iter()
            .map(|(w, b)| (vec![0.0; w.len()], vec![0.0; b.len()]))
            .collect(),
    }
}

/// A training or validation batch: `size` (template, source) pairs of
/// `points` points each and the true pose mapping source onto template.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch {
    /// Pairs in the batch.
    pub size: usize,
    /// Points per cloud.
    pub points: usize,
    /// Templates, `size * points` points.
    pub template: Vec<[f32; 3]>,
    /// Sources, `size * points` points.
    pub source: Vec<[f32; 3]>,
    /// True rotations (source onto template).
    pub r_gt: Vec<Mat3>,
    /// True translations (source onto template).
    pub t_gt: Vec<[f32; 3]>,
    /// Centroid each source had before centring (zero when not centred):
    /// poses of the clouds as made, for validation ([`super::data::make_pair_with_centroid`]).
    pub centroids: Vec<[f32; 3]>,
}

/// Loss, gradient and the estimated poses of one batch.
#[derive(Debug, Clone)]
pub struct StepOutput {
    /// Mean loss over the batch.
    pub loss: f32,
    /// Gradient of the mean loss.
    pub grads: F32Params,
    /// Estimated pose of every pair (composed over the passes).
    pub poses: Vec<(Mat3, [f32; 3])>,
}

/// Runs the passes without gradient; returns the template encoding (kept
/// when `keep`), the moved sources and the accumulated poses.
fn run_passes(
    params: &F32Params,
    passes: usize,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    b: usize,
    n: usize,
    keep_template: bool,
) -> (EncoderCache, Vec<[f32; 3]>, Vec<RigidPose>) {
    let tc = encode(params, template.as_flattened(), b, n, keep_template);
    let mut cur = source.to_vec();
    let mut acc = vec![(IDENTITY, [0f32; 3]); b];
    for _ in 0..passes {
        let sc = encode(params, cur.as_flattened(), b, n, false);
        let hc = head_forward(params, &tc.feature, &sc.feature, b);
        cur.par_chunks_mut(n)
            .zip(acc.par_iter_mut())
            .enumerate()
            .for_each(|(i, (pts, a))| {
                let (r, t) = pose_from_raw(&hc.out[i * 7..i * 7 + 7]);
                for p in pts.iter_mut() {
                    *p = geometry::apply(&r, &t, p);
                }
                *a = compose(&r, &t, &a.0, &a.1);
            });
    }
    (tc, cur, acc)
}

/// Estimated poses (source onto template) for `b` pairs of `n` points
/// after `passes` network passes (at least 1), no gradient.
pub fn predict(
    params: &F32Params,
    passes: usize,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    b: usize,
    n: usize,
) -> Vec<(Mat3, [f32; 3])> {
    run_passes(params, passes.max(1), template, source, b, n, false).2
}

/// Forward and backward of one batch with `passes` network passes (at
/// least 1): mean loss over the pairs, its gradient, and the estimated
/// poses. See the module docs for how gradients pass through i-PCRNet's
/// iterations.
pub fn loss_and_grad(
    params: &F32Params,
    passes: usize,
    loss_kind: LossKind,
    batch: &Batch,
) -> StepOutput {
    let (b, n) = (batch.size, batch.points);
    let (tc, cur, acc) = run_passes(
        params,
        passes.max(1) - 1,
        &batch.template,
        &batch.source,
        b,
        n,
        true,
    );
    let sc = encode(params, cur.as_flattened(), b, n, true);
    let hc = head_forward(params, &tc.feature, &sc.feature, b);
    let scale = 1.0 / b as f32;
    let per: Vec<(f32, [f32; 7], RigidPose)> = (0..b)
        .into_par_iter()
        .map(|i| {
            let raw = &hc.out[i * 7..i * 7 + 7];
            let (r, t) = pose_from_raw(raw);
            let (ra, ta) = acc[i];
            let (l, dr, dt) = match loss_kind {
                LossKind::Chamfer => {
                    let src = &cur[i * n..(i + 1) * n];
                    let moved = geometry::transform_points(&r, &t, src);
                    let (l, dm) = loss::chamfer(&batch.template[i * n..(i + 1) * n], &moved);
                    let (dr, dt) = geometry::transform_points_backward(src, &dm);
                    (l, dr, dt)
                }
                LossKind::Pose => {
                    let (rt, tt) = compose(&r, &t, &ra, &ta);
                    let (l, drt, dtt) = loss::pose_loss(&rt, &tt, &batch.r_gt[i], &batch.t_gt[i]);
                    // R_tot = R Ra, t_tot = R ta + t.
                    let mut dr = mat_mul(&drt, &transpose(&ra));
                    for (r, &g) in dr.iter_mut().zip(&dtt) {
                        for (v, &a) in r.iter_mut().zip(&ta) {
                            *v += g * a;
                        }
                    }
                    (l, dr, dtt)
                }
            };
            let dr = dr.map(|row| row.map(|v| v * scale));
            let dt = dt.map(|v| v * scale);
            let draw = pose_from_raw_backward(raw, &dr, &dt);
            (l, draw, compose(&r, &t, &ra, &ta))
        })
        .collect();
    let mut loss = 0f64;
    let mut dout = Vec::with_capacity(b * 7);
    let mut poses = Vec::with_capacity(b);
    for (l, d, p) in per {
        loss += l as f64;
        dout.extend_from_slice(&d);
        poses.push(p);
    }
    let mut grads = zeros_like(params);
    let (dtf, dsf) = head_backward(params, &hc, &dout, &mut grads);
    encoder_backward(params, &sc, &dsf, &mut grads);
    encoder_backward(params, &tc, &dtf, &mut grads);
    StepOutput {
        loss: (loss / b as f64) as f32,
        grads,
        poses,
    }
}
