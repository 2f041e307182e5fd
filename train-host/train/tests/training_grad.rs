//! Finite-difference gradient checks of every layer, loss and the whole network.

use pcrnet_core::Arch;
use pcrnet_train::F32Params;
use pcrnet_train::forward;
use pcrnet_train::geometry::{
    Mat3, pose_from_raw, pose_from_raw_backward, transform_points, transform_points_backward,
};
use pcrnet_train::loss::{chamfer, chamfer_value, pose_loss};
use pcrnet_train::model::{Batch, ModelKind};
use pcrnet_train::{Dataset, LossKind, PairConfig, initial_params, ops};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rand_vec(rng: &mut ChaCha8Rng, n: usize, lo: f32, hi: f32) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(lo..hi)).collect()
}

/// Values away from 0 (so ReLU kinks are not crossed by the difference step).
fn rand_away(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n)
        .map(|_| {
            let v: f32 = rng.random_range(0.1..1.0);
            if rng.random_bool(0.5) { v } else { -v }
        })
        .collect()
}

fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum()
}

/// Central difference of `f` at `x[i]`.
fn fd(x: &mut [f32], i: usize, eps: f32, f: &mut dyn FnMut(&[f32]) -> f64) -> f64 {
    let v = x[i];
    x[i] = v + eps;
    let hi = f(x);
    x[i] = v - eps;
    let lo = f(x);
    x[i] = v;
    (hi - lo) / (2.0 * eps as f64)
}

/// Checks every coordinate of `analytic` against central differences.
fn check(
    name: &str,
    x: &mut [f32],
    analytic: &[f32],
    eps: f32,
    tol: f64,
    f: &mut dyn FnMut(&[f32]) -> f64,
) {
    assert_eq!(x.len(), analytic.len(), "{name}: sizes");
    for (i, &an) in analytic.iter().enumerate() {
        let num = fd(x, i, eps, f);
        let an = an as f64;
        let err = (num - an).abs();
        assert!(
            err <= tol * (1.0 + an.abs().max(num.abs())),
            "{name}[{i}]: numeric {num} analytic {an}"
        );
    }
}

#[test]
fn dense_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (rows, inp, out) = (5, 4, 3);
    let mut x = rand_vec(&mut rng, rows * inp, -1.0, 1.0);
    let mut w = rand_vec(&mut rng, out * inp, -1.0, 1.0);
    let mut b = rand_vec(&mut rng, out, -1.0, 1.0);
    let r = rand_vec(&mut rng, rows * out, -1.0, 1.0);
    let (mut dw, mut db, mut dx) = (vec![0.0; w.len()], vec![0.0; out], vec![0.0; x.len()]);
    ops::dense_backward(&x, &w, &r, rows, &mut dw, &mut db, Some(&mut dx));
    let loss = |x: &[f32], w: &[f32], b: &[f32]| {
        let mut y = vec![0.0; rows * out];
        ops::dense_forward(x, w, b, rows, &mut y);
        dot(&y, &r)
    };
    let (w0, b0, x0) = (w.clone(), b.clone(), x.clone());
    check("dW", &mut w, &dw, 1e-2, 1e-3, &mut |w| loss(&x0, w, &b0));
    check("db", &mut b, &db, 1e-2, 1e-3, &mut |b| loss(&x0, &w0, b));
    check("dx", &mut x, &dx, 1e-2, 1e-3, &mut |x| loss(x, &w0, &b0));
}

#[test]
fn relu_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut x = rand_away(&mut rng, 20);
    let r = rand_vec(&mut rng, 20, -1.0, 1.0);
    let mut y = x.clone();
    ops::relu(&mut y);
    let mut dx = r.clone();
    ops::relu_backward(&y, &mut dx);
    check("relu", &mut x, &dx, 1e-3, 1e-3, &mut |x| {
        let mut y = x.to_vec();
        ops::relu(&mut y);
        dot(&y, &r)
    });
}

#[test]
fn maxpool_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (clouds, n, c) = (2, 6, 4);
    let mut x = rand_vec(&mut rng, clouds * n * c, -1.0, 1.0);
    let r = rand_vec(&mut rng, clouds * c, -1.0, 1.0);
    let (_, arg) = ops::maxpool_forward(&x, clouds, n, c);
    let dx = ops::maxpool_backward(&arg, &r, clouds, n, c);
    check("maxpool", &mut x, &dx, 1e-4, 1e-2, &mut |x| {
        dot(&ops::maxpool_forward(x, clouds, n, c).0, &r)
    });
}

#[test]
fn fused_dense_maxpool_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let (clouds, n, inp, out) = (3, 5, 4, 6);
    let mut x = rand_vec(&mut rng, clouds * n * inp, -1.0, 1.0);
    let mut w = rand_vec(&mut rng, out * inp, -1.0, 1.0);
    let mut b = rand_vec(&mut rng, out, -1.0, 1.0);
    let r = rand_vec(&mut rng, clouds * out, -1.0, 1.0);
    // The fused forward equals dense then max-pool.
    let mut y = vec![0.0; clouds * n * out];
    ops::dense_forward(&x, &w, &b, clouds * n, &mut y);
    let (v1, a1) = ops::maxpool_forward(&y, clouds, n, out);
    let (v2, a2) = ops::dense_maxpool_forward(&x, &w, &b, clouds, n, 2);
    assert_eq!((v1, a1), (v2, a2.clone()));
    let (mut dw, mut db, mut dx) = (vec![0.0; w.len()], vec![0.0; out], vec![0.0; x.len()]);
    ops::dense_maxpool_backward(&x, &w, &a2, &r, clouds, n, &mut dw, &mut db, Some(&mut dx));
    let loss = |x: &[f32], w: &[f32], b: &[f32]| {
        dot(&ops::dense_maxpool_forward(x, w, b, clouds, n, 1).0, &r)
    };
    let (w0, b0, x0) = (w.clone(), b.clone(), x.clone());
    check("dW", &mut w, &dw, 1e-3, 1e-2, &mut |w| loss(&x0, w, &b0));
    check("db", &mut b, &db, 1e-3, 1e-2, &mut |b| loss(&x0, &w0, b));
    check("dx", &mut x, &dx, 1e-3, 1e-2, &mut |x| loss(x, &w0, &b0));
}

fn to_points(v: &[f32]) -> Vec<[f32; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

#[test]
fn pose_transform_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..4 {
        let mut raw = rand_vec(&mut rng, 7, -1.0, 1.0);
        raw[0] += 1.5;
        let pts = to_points(&rand_vec(&mut rng, 18, -1.0, 1.0));
        let r = rand_vec(&mut rng, 18, -1.0, 1.0);
        let (dr, dt) = transform_points_backward(&pts, &to_points(&r));
        let draw = pose_from_raw_backward(&raw, &dr, &dt);
        check("raw", &mut raw, &draw, 1e-3, 5e-3, &mut |raw| {
            let (rm, t) = pose_from_raw(raw);
            dot(transform_points(&rm, &t, &pts).as_flattened(), &r)
        });
    }
}

#[test]
fn chamfer_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let a = to_points(&rand_vec(&mut rng, 21, -1.0, 1.0));
    let mut b = rand_vec(&mut rng, 18, -1.0, 1.0);
    let (l, db) = chamfer(&a, &to_points(&b));
    assert!((l - chamfer_value(&a, &to_points(&b))).abs() < 1e-6);
    check("chamfer", &mut b, db.as_flattened(), 1e-3, 5e-3, &mut |b| {
        chamfer_value(&a, &to_points(b)) as f64
    });
    assert!(chamfer_value(&a, &a) == 0.0);
}

#[test]
fn pose_loss_gradient() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let rgt: Mat3 = pose_from_raw(&rand_vec(&mut rng, 7, 0.1, 1.0)).0;
    let tgt = [0.1, -0.2, 0.3];
    let mut x = rand_vec(&mut rng, 12, -1.0, 1.0);
    let split = |x: &[f32]| -> (Mat3, [f32; 3]) {
        (
            [[x[0], x[1], x[2]], [x[3], x[4], x[5]], [x[6], x[7], x[8]]],
            [x[9], x[10], x[11]],
        )
    };
    let (r, t) = split(&x);
    let (_, dr, dt) = pose_loss(&r, &t, &rgt, &tgt);
    let mut an = dr.as_flattened().to_vec();
    an.extend_from_slice(&dt);
    check("pose loss", &mut x, &an, 1e-3, 1e-3, &mut |x| {
        let (r, t) = split(x);
        pose_loss(&r, &t, &rgt, &tgt).0 as f64
    });
}

fn tiny_batch(seed: u64, b: usize, n: usize) -> Batch {
    let ds = Dataset::generated(b, n, seed);
    let shapes: Vec<usize> = (0..b).collect();
    let seeds: Vec<u64> = (0..b as u64).map(|i| seed * 100 + i).collect();
    let cfg = PairConfig {
        max_deg: 30.0,
        max_t: 0.3,
        ..PairConfig::default()
    };
    ds.batch(&shapes, &seeds, &cfg, false)
}

fn flat(p: &F32Params) -> Vec<f32> {
    p.layers
        .iter()
        .flat_map(|(w, b)| w.iter().chain(b).copied())
        .collect()
}

fn unflat(p: &mut F32Params, v: &[f32]) {
    let mut k = 0;
    for (w, b) in &mut p.layers {
        for x in w.iter_mut().chain(b.iter_mut()) {
            *x = v[k];
            k += 1;
        }
    }
}

/// Smallest gap between the nearest and second-nearest squared distances
/// over both Chamfer directions: a near-tie is a kink that a central
/// difference would straddle.
fn min_nn_gap(batch: &Batch, poses: &[(Mat3, [f32; 3])]) -> f32 {
    let n = batch.points;
    let gap = |p: &[f32; 3], set: &[[f32; 3]]| {
        let mut d: Vec<f32> = set
            .iter()
            .map(|q| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum())
            .collect();
        d.sort_by(f32::total_cmp);
        d[1] - d[0]
    };
    let mut m = f32::INFINITY;
    for (i, (r, t)) in poses.iter().enumerate() {
        let moved = transform_points(r, t, &batch.source[i * n..(i + 1) * n]);
        let a = &batch.template[i * n..(i + 1) * n];
        for p in a {
            m = m.min(gap(p, &moved));
        }
        for p in &moved {
            m = m.min(gap(p, a));
        }
    }
    m
}

/// Whole-network check on a tiny architecture: every parameter, both losses.
/// For Chamfer, the first seed without a nearest-neighbour near-tie is used
/// (a tie is a kink of the loss). ReLU and max-pool kinks can still make a
/// rare central difference straddle a kink: 95% of the coordinates must
/// agree with the central difference within 2%, and every other one with a
/// one-sided difference within 10%.
#[test]
fn whole_network_gradient() {
    let arch = Arch::new(&[4, 5], &[6]).unwrap();
    for loss in [LossKind::Chamfer, LossKind::Pose] {
        let (params, batch) = (10..)
            .map(|seed| {
                let mut params = initial_params(arch.clone(), seed);
                // Larger output weights than the training initialisation,
                // so every layer gets a sizeable gradient.
                if let Some((w, _)) = params.layers.last_mut() {
                    for v in w.iter_mut() {
                        *v *= 30.0;
                    }
                }
                (params, tiny_batch(seed, 2, 8))
            })
            .find(|(p, b)| {
                let poses = forward::predict(p, ModelKind::Pcrnet, &b.template, &b.source, 2, 8);
                loss == LossKind::Pose || min_nn_gap(b, &poses) > 5e-3
            })
            .unwrap();
        let out = forward::loss_and_grad(&params, ModelKind::Pcrnet, loss, &batch);
        let an = flat(&out.grads);
        let mut probe = params.clone();
        agrees_with_differences(&format!("{loss:?}"), &an, &mut flat(&params), &mut |v| {
            unflat(&mut probe, v);
            forward::loss_and_grad(&probe, ModelKind::Pcrnet, loss, &batch).loss as f64
        });
        assert!(an.iter().filter(|g| g.abs() > 1e-4).count() > an.len() / 2);
    }
}

/// Checks a whole model's gradient `an` at the parameters `x` against
/// central differences of the loss `f`: 95% of the coordinates within 2%,
/// and every other one within 10% of a one-sided difference (a ReLU or
/// max-pool kink straddled by the central difference).
fn agrees_with_differences(
    label: &str,
    an: &[f32],
    x: &mut [f32],
    f: &mut dyn FnMut(&[f32]) -> f64,
) {
    let mut close = 0;
    for i in 0..x.len() {
        let num = fd(x, i, 1e-3, f);
        let a = an[i] as f64;
        let err = (num - a).abs();
        let scale = 1e-3 + a.abs().max(num.abs());
        if err <= 2e-2 * scale {
            close += 1;
            continue;
        }
        // At a kink the analytic gradient is one of the one-sided ones.
        let v = x[i];
        let f0 = f(x);
        let mut sided = Vec::new();
        for h in [1e-3f32, 1e-4] {
            x[i] = v + h;
            sided.push((f(x) - f0) / h as f64);
            x[i] = v - h;
            sided.push((f0 - f(x)) / h as f64);
        }
        x[i] = v;
        assert!(
            sided
                .iter()
                .any(|s| (s - a).abs() <= 0.1 * (1e-3 + a.abs().max(s.abs()))),
            "{label} param {i}: numeric {num} one-sided {sided:?} analytic {a}"
        );
    }
    assert!(
        close as f64 >= 0.95 * x.len() as f64,
        "{label}: only {close}/{} close",
        x.len()
    );
}

/// Points per cloud of the PointNetLK checks: enough that the max-pool's
/// winners change rarely along a difference step.
const LK_POINTS: usize = 32;

/// PointNetLK with one LK iteration: the gradient through the Jacobian's
/// seven template encodings and the source's agrees with central
/// differences of the Chamfer loss along random directions of the encoder's
/// parameters; the head, which PointNetLK does not use, gets none. (The
/// encoder's feature is 12 wide: at least the twist's 6, so that the
/// normal equations are regular.) The f32 loss is too rough for a
/// difference along a single coordinate, and the pose loss's slopes too
/// small against its rounding (the Jacobian's `1 / 0.01` scales the
/// features' rounding): the LK layer's own backward is checked entry by
/// entry in f64 (`lk`'s unit tests) and the pose loss's on its own above;
/// this checks how they are wired to the encoder.
#[test]
fn pointnetlk_gradient() {
    let arch = Arch::new(&[8, 12], &[6]).unwrap();
    let lk = ModelKind::PointNetLk { iterations: 1 };
    let encoder_len: usize = 3 * 8 + 8 + 8 * 12 + 12;
    let n = LK_POINTS;
    let (params, batch) = (20..)
        .map(|seed| (initial_params(arch.clone(), seed), tiny_batch(seed, 2, n)))
        .find(|(p, b)| min_nn_gap(b, &forward::predict(p, lk, &b.template, &b.source, 2, n)) > 1e-4)
        .unwrap();
    let out = forward::loss_and_grad(&params, lk, LossKind::Chamfer, &batch);
    let an = flat(&out.grads);
    assert!(an[encoder_len..].iter().all(|&g| g == 0.0), "head gradient");
    let live = an[..encoder_len].iter().filter(|g| g.abs() > 1e-5).count();
    assert!(live > encoder_len / 2, "{live} of {encoder_len} live");
    let x = flat(&params);
    let mut probe = params.clone();
    let mut f = |v: &[f32]| {
        unflat(&mut probe, v);
        forward::loss_and_grad(&probe, lk, LossKind::Chamfer, &batch).loss as f64
    };
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for direction in 0..4 {
        let v: Vec<f32> = (0..x.len())
            .map(|i| {
                if i < encoder_len {
                    rng.random_range(-1.0..1.0)
                } else {
                    0.0
                }
            })
            .collect();
        let slope = dot(&an, &v);
        let along = |eps: f32| -> Vec<f32> { x.iter().zip(&v).map(|(a, b)| a + eps * b).collect() };
        let numeric: Vec<f64> = [1e-3f32, 3e-4]
            .iter()
            .map(|&eps| (f(&along(eps)) - f(&along(-eps))) / (2.0 * eps as f64))
            .collect();
        assert!(
            numeric
                .iter()
                .any(|n| (n - slope).abs() <= 2e-2 * (1e-3 + slope.abs().max(n.abs()))),
            "direction {direction}: analytic {slope}, differences {numeric:?}"
        );
    }
    // The loss is the pose's, and the poses are predict's.
    let poses = forward::predict(&params, lk, &batch.template, &batch.source, 2, n);
    assert_eq!(poses, out.poses);
}

/// PointNetLK's gradient with two iterations is the one-iteration gradient
/// on the sources moved by the first (the earlier iterations are data).
#[test]
fn pointnetlk_gradient_is_last_iteration() {
    let arch = Arch::new(&[8, 12], &[6]).unwrap();
    let params = initial_params(arch, 5);
    let batch = tiny_batch(5, 2, 8);
    let one = ModelKind::PointNetLk { iterations: 1 };
    let two = forward::loss_and_grad(
        &params,
        ModelKind::PointNetLk { iterations: 2 },
        LossKind::Chamfer,
        &batch,
    );
    let first = forward::predict(&params, one, &batch.template, &batch.source, 2, 8);
    let mut moved = batch.clone();
    for (i, (r, t)) in first.iter().enumerate() {
        let pts = transform_points(r, t, &batch.source[i * 8..(i + 1) * 8]);
        moved.source[i * 8..(i + 1) * 8].copy_from_slice(&pts);
    }
    let last = forward::loss_and_grad(&params, one, LossKind::Chamfer, &moved);
    assert!(
        (two.loss - last.loss).abs() <= 1e-4 * (1.0 + last.loss.abs()),
        "{} {}",
        two.loss,
        last.loss
    );
    for (g1, g2) in flat(&two.grads).iter().zip(flat(&last.grads)) {
        assert!((g1 - g2).abs() <= 1e-3 * (1.0 + g2.abs()), "{g1} {g2}");
    }
}

/// i-PCRNet with one pass is PCRNet; with more passes its gradient is the
/// last pass's (the earlier ones are data).
#[test]
fn ipcrnet_gradient_is_last_pass() {
    let arch = Arch::new(&[4, 5], &[6]).unwrap();
    let params = initial_params(arch, 3);
    let batch = tiny_batch(3, 2, 8);
    let a = forward::loss_and_grad(&params, ModelKind::Pcrnet, LossKind::Chamfer, &batch);
    let b = forward::loss_and_grad(
        &params,
        ModelKind::Ipcrnet { iterations: 1 },
        LossKind::Chamfer,
        &batch,
    );
    assert_eq!(flat(&a.grads), flat(&b.grads));
    // Two passes = PCRNet's gradient on the batch whose sources were moved
    // by the first pass.
    let two = forward::loss_and_grad(
        &params,
        ModelKind::Ipcrnet { iterations: 2 },
        LossKind::Chamfer,
        &batch,
    );
    let first = forward::predict(
        &params,
        ModelKind::Pcrnet,
        &batch.template,
        &batch.source,
        2,
        8,
    );
    let mut moved = batch.clone();
    for (i, (r, t)) in first.iter().enumerate() {
        let pts = transform_points(r, t, &batch.source[i * 8..(i + 1) * 8]);
        moved.source[i * 8..(i + 1) * 8].copy_from_slice(&pts);
    }
    let last = forward::loss_and_grad(&params, ModelKind::Pcrnet, LossKind::Chamfer, &moved);
    assert!((two.loss - last.loss).abs() < 1e-6);
    for (g1, g2) in flat(&two.grads).iter().zip(flat(&last.grads)) {
        assert!((g1 - g2).abs() <= 1e-5 * (1.0 + g2.abs()));
    }
}
