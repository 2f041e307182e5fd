//! PointNetLK (Aoki et al., *PointNetLK: Robust & Efficient Point Cloud
//! Registration using PointNet*, CVPR 2019), trained as the paper trains
//! it: the encoder learns through the Lucas-Kanade layer.
//!
//! # The LK layer (inverse compositional)
//! For a template `T` and a source `S` (`n` points each, the model frame)
//! and the encoder's global feature `phi` (`F` values, after the max-pool
//! and its ReLU):
//! - the Jacobian of the template's feature with respect to a twist
//!   `xi = (omega, v)`, by forward differences of step
//!   [`JACOBIAN_STEP`] (the paper's `1e-2`):
//!   `J[:, k] = (phi(exp(d e_k) T) - phi(T)) / d`, `F x 6`;
//! - each iteration, with `G` the pose so far (identity at first):
//!   `r = phi(G S) - phi(T)`, `dxi = (J^T J + lambda I)^-1 J^T r`,
//!   `G <- exp(dxi)^-1 G`, so that `G S` moves onto `T`;
//! - `lambda` is [`DAMPING`] times the mean diagonal of `J^T J`, so that
//!   a Jacobian with a dead direction still gives a finite step.
//!
//! # Gradients
//! Training runs a fixed number of iterations. **Gradients flow through the
//! last iteration only**, as i-PCRNet's through its last pass
//! ([`crate::model`]): the poses of the earlier iterations are data. The
//! last one's gradient reaches every parameter by three paths: the
//! source's feature `phi(G S)`, the template's `phi(T)` and the six moved
//! templates' `phi(exp(d e_k) T)` through `J`. With `g = dL/d dxi`,
//! `A = J^T J + lambda I`, `u = A^-1 g`: `dL/dr = J u` and
//! `dL/dJ = r u^T - J (dxi u^T + u dxi^T) - 2 c (u . dxi) J` (the last
//! term the damping's, `lambda = c tr(J^T J)`). `dL/d dxi`
//! itself comes from the loss's gradient on the final `(R, t)` through
//! `exp(dxi)^-1 G` by central differences in f64 (six directions of a
//! closed-form map, step [`TWIST_STEP`]).
//!
//! The original PointNetLK backpropagates through every iteration; with
//! the last one only, the activations kept are those of one iteration
//! (eight encodings of each pair: the template, its six moves, the source),
//! and each earlier iteration costs one more encoding of the source,
//! without gradient.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Rotation3, Vector3, Vector6};
use rayon::prelude::*;

use crate::F32Params;
use crate::geometry::{self, Mat3};
use crate::loss::{self, LossKind};
use crate::model::{
    Batch, EncoderCache, RigidPose, StepOutput, encode, encoder_backward, zeros_like,
};

/// Step of the Jacobian's forward differences (twist units: radians and
/// model units), the paper's `1e-2`.
pub const JACOBIAN_STEP: f64 = 1e-2;

/// Damping of the normal equations, relative to the mean diagonal of
/// `J^T J`: small enough not to bias a well-conditioned step.
pub const DAMPING: f64 = 1e-6;

/// Step of the central differences of `exp(dxi)^-1 G` in `dxi`.
pub const TWIST_STEP: f64 = 1e-6;

/// A rigid transform in f64: `p -> r p + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid64 {
    /// Rotation.
    pub r: Matrix3<f64>,
    /// Translation.
    pub t: Vector3<f64>,
}

impl Rigid64 {
    /// The identity.
    pub const IDENTITY: Rigid64 = Rigid64 {
        r: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        t: Vector3::new(0.0, 0.0, 0.0),
    };

    /// The se(3) exponential of a twist `(omega, v)`: rotation by Rodrigues,
    /// translation the left Jacobian of SO(3) times `v`.
    pub fn exp(xi: &Vector6<f64>) -> Rigid64 {
        let w = Vector3::new(xi[0], xi[1], xi[2]);
        let v = Vector3::new(xi[3], xi[4], xi[5]);
        let theta = w.norm();
        let k = w.cross_matrix();
        let (a, b) = if theta < 1e-8 {
            (0.5, 1.0 / 6.0)
        } else {
            (
                (1.0 - theta.cos()) / (theta * theta),
                (theta - theta.sin()) / (theta * theta * theta),
            )
        };
        let r = Rotation3::new(w).into_inner();
        let jl = Matrix3::identity() + k * a + k * k * b;
        Rigid64 { r, t: jl * v }
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Rigid64 {
        let rt = self.r.transpose();
        Rigid64 {
            r: rt,
            t: -(rt * self.t),
        }
    }

    /// `self` after `other`: `p -> self(other(p))`.
    pub fn after(&self, other: &Rigid64) -> Rigid64 {
        Rigid64 {
            r: self.r * other.r,
            t: self.r * other.t + self.t,
        }
    }

    /// The transform applied to `pts` (computed in f64, stored in f32).
    pub fn apply(&self, pts: &[[f32; 3]]) -> Vec<[f32; 3]> {
        pts.iter()
            .map(|p| {
                let q = self.r * Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) + self.t;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect()
    }

    /// As the training code's f32 `(R, t)`.
    pub fn to_f32(&self) -> RigidPose {
        (
            std::array::from_fn(|i| std::array::from_fn(|j| self.r[(i, j)] as f32)),
            std::array::from_fn(|i| self.t[i] as f32),
        )
    }
}

/// One template's Lucas-Kanade solver: the Jacobian and the factorised
/// normal equations.
#[derive(Debug, Clone)]
pub struct LkSolver {
    jacobian: DMatrix<f64>,
    /// `(J^T J + lambda I)^-1`; zero when it does not exist (a Jacobian
    /// of zeros): every step is then zero.
    normal_inverse: Matrix6<f64>,
}

impl LkSolver {
    /// The solver of the Jacobian `J` (`F x 6`).
    pub fn new(jacobian: DMatrix<f64>) -> Self {
        let jtj: Matrix6<f64> = {
            let m = jacobian.transpose() * &jacobian;
            Matrix6::from_fn(|i, j| m[(i, j)])
        };
        let lambda = DAMPING * jtj.trace() / 6.0;
        let normal_inverse = (jtj + Matrix6::identity() * lambda)
            .try_inverse()
            .filter(|m| m.iter().all(|v| v.is_finite()))
            .unwrap_or_else(Matrix6::zeros);
        LkSolver {
            jacobian,
            normal_inverse,
        }
    }

    /// The solver of a template whose feature is `phi` and whose six moved
    /// copies (`exp(d e_k) T`, `k = 0..6`) have features `moved[k]`.
    pub fn from_features(phi: &DVector<f64>, moved: [&DVector<f64>; 6]) -> Self {
        let mut jacobian = DMatrix::zeros(phi.len(), 6);
        for (k, m) in moved.iter().enumerate() {
            jacobian.set_column(k, &((*m - phi) / JACOBIAN_STEP));
        }
        Self::new(jacobian)
    }

    /// `P = (J^T J + lambda I)^-1 J^T` (`6 x F`): the step is `P r`.
    pub fn pseudo_inverse(&self) -> DMatrix<f64> {
        let n = DMatrix::from_fn(6, 6, |i, j| self.normal_inverse[(i, j)]);
        n * self.jacobian.transpose()
    }

    /// The step `dxi` for the feature residual `r = phi(G S) - phi(T)`.
    pub fn step(&self, residual: &DVector<f64>) -> Vector6<f64> {
        let jtr = self.jacobian.transpose() * residual;
        self.normal_inverse * Vector6::from_iterator(jtr.iter().copied())
    }
}

/// The six moved copies of a template for its Jacobian, `exp(d e_k) T`.
pub fn moved_templates(template: &[[f32; 3]]) -> [Vec<[f32; 3]>; 6] {
    std::array::from_fn(|k| {
        let mut xi = Vector6::zeros();
        xi[k] = JACOBIAN_STEP;
        Rigid64::exp(&xi).apply(template)
    })
}

/// Encodes, for each of `b` pairs, its template and the template's six
/// moved copies: `7 b` clouds, pair `i`'s at `7 i .. 7 i + 7`.
fn encode_templates(
    params: &F32Params,
    template: &[[f32; 3]],
    b: usize,
    n: usize,
    keep: bool,
) -> EncoderCache {
    let clouds: Vec<[f32; 3]> = template
        .par_chunks(n)
        .take(b)
        .flat_map_iter(|t| {
            let moved = moved_templates(t);
            let mut all = t.to_vec();
            for m in moved {
                all.extend(m);
            }
            all
        })
        .collect();
    encode(params, clouds.as_flattened(), 7 * b, n, keep)
}

fn feature_of(cache: &EncoderCache, cloud: usize, f: usize) -> &[f32] {
    &cache.feature[cloud * f..(cloud + 1) * f]
}

/// Cloud `c`'s feature in f64.
fn feature64(cache: &EncoderCache, c: usize, f: usize) -> DVector<f64> {
    DVector::from_iterator(f, feature_of(cache, c, f).iter().map(|&v| v as f64))
}

fn solvers(cache: &EncoderCache, b: usize, f: usize) -> Vec<LkSolver> {
    (0..b)
        .into_par_iter()
        .map(|i| {
            let moved: [DVector<f64>; 6] =
                std::array::from_fn(|k| feature64(cache, 7 * i + 1 + k, f));
            LkSolver::from_features(
                &feature64(cache, 7 * i, f),
                std::array::from_fn(|k| &moved[k]),
            )
        })
        .collect()
}

fn residual(source: &[f32], template: &[f32]) -> DVector<f64> {
    DVector::from_iterator(
        source.len(),
        source
            .iter()
            .zip(template)
            .map(|(&s, &t)| s as f64 - t as f64),
    )
}

/// One pair's last LK iteration, kept for its backward.
#[derive(Debug, Clone)]
pub struct LastStep<'a> {
    solver: &'a LkSolver,
    residual: DVector<f64>,
    dxi: Vector6<f64>,
    before: Rigid64,
    /// The pose after the step: `exp(dxi)^-1 before`.
    pub pose: Rigid64,
}

impl<'a> LastStep<'a> {
    /// The step from the pose `before` with the feature residual
    /// `r = phi(before S) - phi(T)`.
    pub fn new(solver: &'a LkSolver, residual: DVector<f64>, before: Rigid64) -> Self {
        let dxi = solver.step(&residual);
        LastStep {
            solver,
            residual,
            dxi,
            before,
            pose: Rigid64::exp(&dxi).inverse().after(&before),
        }
    }

    /// From the loss's gradient on the pose (`dr` on its rotation, `dt`
    /// on its translation), the gradients on the moved source's feature
    /// (`F`) and on the template's seven features (`7 F`: `T`, then its
    /// six moves). See the module docs.
    pub fn backward(&self, dr: &Matrix3<f64>, dt: &Vector3<f64>) -> (DVector<f64>, DVector<f64>) {
        let g = twist_gradient(&self.dxi, &self.before, dr, dt);
        let u = self.solver.normal_inverse * g;
        let j = &self.solver.jacobian;
        let f = j.nrows();
        let ju: DVector<f64> = j * DVector::from_iterator(6, u.iter().copied());
        let jdxi: DVector<f64> = j * DVector::from_iterator(6, self.dxi.iter().copied());
        // The damping `lambda = c tr(J^T J)` moves with J too:
        // dL/dlambda = -u . dxi, dlambda/dJ = 2 c J.
        let damping = -2.0 * DAMPING / 6.0 * u.dot(&self.dxi);
        let mut dtemplates = DVector::zeros(7 * f);
        for k in 0..6 {
            for row in 0..f {
                // dL/dJ[row, k] = (r - J dxi)[row] u_k - (J u)[row] dxi_k
                // (+ the damping's part), and J[:, k] = (phi(T_k) - phi(T)) / d.
                let d = ((self.residual[row] - jdxi[row]) * u[k] - ju[row] * self.dxi[k]
                    + damping * j[(row, k)])
                    / JACOBIAN_STEP;
                dtemplates[(1 + k) * f + row] = d;
                dtemplates[row] -= d;
            }
        }
        // r = phi(G S) - phi(T): dL/dr = J u.
        for row in 0..f {
            dtemplates[row] -= ju[row];
        }
        (ju, dtemplates)
    }
}

/// Every pair's source (`n` points each) moved by its pose.
fn moved(poses: &[Rigid64], source: &[[f32; 3]], n: usize) -> Vec<[f32; 3]> {
    poses
        .par_iter()
        .zip(source.par_chunks(n))
        .flat_map_iter(|(g, s)| g.apply(s))
        .collect()
}

/// Runs `iterations` LK iterations on every pair without gradient; returns
/// the template encodings, the solvers and the poses.
fn iterate(
    params: &F32Params,
    iterations: usize,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    b: usize,
    n: usize,
    keep_template: bool,
) -> (EncoderCache, Vec<LkSolver>, Vec<Rigid64>) {
    let f = params.arch.feature_dim();
    let tc = encode_templates(params, template, b, n, keep_template);
    let solvers = solvers(&tc, b, f);
    let mut poses = vec![Rigid64::IDENTITY; b];
    for _ in 0..iterations {
        let sc = encode(params, moved(&poses, source, n).as_flattened(), b, n, false);
        poses.par_iter_mut().enumerate().for_each(|(i, g)| {
            let r = residual(feature_of(&sc, i, f), feature_of(&tc, 7 * i, f));
            *g = Rigid64::exp(&solvers[i].step(&r)).inverse().after(g);
        });
    }
    (tc, solvers, poses)
}

/// Estimated poses (source onto template) of `b` pairs of `n` points after
/// `iterations` LK iterations, no gradient.
pub fn predict(
    params: &F32Params,
    iterations: usize,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    b: usize,
    n: usize,
) -> Vec<RigidPose> {
    iterate(params, iterations, template, source, b, n, false)
        .2
        .iter()
        .map(Rigid64::to_f32)
        .collect()
}

/// `dL/d dxi` from the loss's gradient `(dr, dt)` on the pose
/// `exp(dxi)^-1 G`, by central differences of that map.
fn twist_gradient(
    dxi: &Vector6<f64>,
    g: &Rigid64,
    dr: &Matrix3<f64>,
    dt: &Vector3<f64>,
) -> Vector6<f64> {
    let pose = |x: &Vector6<f64>| Rigid64::exp(x).inverse().after(g);
    Vector6::from_fn(|j, _| {
        let mut e = Vector6::zeros();
        e[j] = TWIST_STEP;
        let (hi, lo) = (pose(&(dxi + e)), pose(&(dxi - e)));
        (dr.component_mul(&(hi.r - lo.r)).sum() + dt.dot(&(hi.t - lo.t))) / (2.0 * TWIST_STEP)
    })
}

/// The loss of one pair at the pose `(r, t)` (source onto template) and its
/// gradient with respect to `r` and `t`.
fn pair_loss(
    kind: LossKind,
    (r, t): &RigidPose,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    truth: (&Mat3, &[f32; 3]),
) -> (f32, Mat3, [f32; 3]) {
    match kind {
        LossKind::Pose => loss::pose_loss(r, t, truth.0, truth.1),
        LossKind::Chamfer => {
            let moved = geometry::transform_points(r, t, source);
            let (l, dm) = loss::chamfer(template, &moved);
            let (dr, dt) = geometry::transform_points_backward(source, &dm);
            (l, dr, dt)
        }
    }
}

/// Forward and backward of one batch of PointNetLK with `iterations` LK
/// iterations (at least 1): the mean loss over the pairs, its gradient
/// (the head's is zero: PointNetLK has none) and the estimated poses. See
/// the module docs.
pub fn loss_and_grad(
    params: &F32Params,
    iterations: usize,
    loss_kind: LossKind,
    batch: &Batch,
) -> StepOutput {
    let (b, n) = (batch.size, batch.points);
    let f = params.arch.feature_dim();
    let (tc, solvers, before) = iterate(
        params,
        iterations.max(1) - 1,
        &batch.template,
        &batch.source,
        b,
        n,
        true,
    );
    let sc = encode(
        params,
        moved(&before, &batch.source, n).as_flattened(),
        b,
        n,
        true,
    );
    let scale = 1.0 / b as f64;
    // Per pair: loss, pose, the gradients on the source's feature and on
    // the template's seven features.
    let per: Vec<(f32, RigidPose, Vec<f32>, Vec<f32>)> = (0..b)
        .into_par_iter()
        .map(|i| {
            let r = residual(feature_of(&sc, i, f), feature_of(&tc, 7 * i, f));
            let last = LastStep::new(&solvers[i], r, before[i]);
            let pose32 = last.pose.to_f32();
            let (l, dr, dt) = pair_loss(
                loss_kind,
                &pose32,
                &batch.template[i * n..(i + 1) * n],
                &batch.source[i * n..(i + 1) * n],
                (&batch.r_gt[i], &batch.t_gt[i]),
            );
            let dr = Matrix3::from_fn(|a, c| dr[a][c] as f64 * scale);
            let dt = Vector3::from_fn(|a, _| dt[a] as f64 * scale);
            let (ds, dtemplates) = last.backward(&dr, &dt);
            let narrow = |v: DVector<f64>| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
            (l, pose32, narrow(ds), narrow(dtemplates))
        })
        .collect();
    let mut loss = 0f64;
    let mut poses = Vec::with_capacity(b);
    let mut dsf = Vec::with_capacity(b * f);
    let mut dtf = Vec::with_capacity(7 * b * f);
    for (l, p, ds, dt) in per {
        loss += l as f64;
        poses.push(p);
        dsf.extend(ds);
        dtf.extend(dt);
    }
    let mut grads = zeros_like(params);
    encoder_backward(params, &sc, &dsf, &mut grads);
    encoder_backward(params, &tc, &dtf, &mut grads);
    StepOutput {
        loss: (loss * scale) as f32,
        grads,
        poses,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_and_inverse_are_consistent() {
        let xi = Vector6::new(0.1, -0.2, 0.3, 0.5, -0.1, 0.2);
        let g = Rigid64::exp(&xi);
        let id = g.inverse().after(&g);
        assert!((id.r - Matrix3::identity()).norm() < 1e-12);
        assert!(id.t.norm() < 1e-12);
        // A pure translation twist moves by v.
        let t = Rigid64::exp(&Vector6::new(0.0, 0.0, 0.0, 1.0, 2.0, 3.0));
        assert!((t.t - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-12);
    }

    #[test]
    fn a_dead_jacobian_gives_zero_steps() {
        let solver = LkSolver::new(DMatrix::zeros(8, 6));
        let step = solver.step(&DVector::from_element(8, 1.0));
        assert_eq!(step, Vector6::zeros());
    }

    /// The last iteration's backward, coordinate by coordinate against
    /// central differences, all in f64: features of a made-up template
    /// (its six moves a well-conditioned Jacobian), a source's feature,
    /// and a loss `|R - R0|^2 + |t - t0|^2`.
    #[test]
    fn last_step_backward_matches_differences() {
        let f = 9;
        let wave = |i: usize, k: usize| ((i * 5 + k * 3) as f64 * 0.7).sin();
        let phi_t = DVector::from_fn(f, |i, _| 1.0 + 0.3 * wave(i, 7));
        let moves: Vec<DVector<f64>> = (0..6)
            .map(|k| {
                DVector::from_fn(f, |i, _| {
                    phi_t[i] + JACOBIAN_STEP * (f64::from(u8::from(i == k)) + 0.5 * wave(i, k))
                })
            })
            .collect();
        let phi_s = DVector::from_fn(f, |i, _| phi_t[i] + 0.05 * wave(i, 11));
        let before = Rigid64::exp(&Vector6::new(0.1, -0.05, 0.2, 0.1, 0.0, -0.1));
        let (r0, t0) = (
            Rotation3::new(Vector3::new(0.2, 0.1, 0.0)).into_inner(),
            Vector3::new(0.1, 0.2, -0.3),
        );
        // All eight features flat: T, its six moves, the source.
        let mut x: Vec<f64> = phi_t.iter().copied().collect();
        for m in &moves {
            x.extend(m.iter());
        }
        x.extend(phi_s.iter());
        let loss = |x: &[f64]| -> (f64, Rigid64, LkSolver) {
            let part = |c: usize| DVector::from_column_slice(&x[c * f..(c + 1) * f]);
            let moved: [DVector<f64>; 6] = std::array::from_fn(|k| part(1 + k));
            let solver = LkSolver::from_features(&part(0), std::array::from_fn(|k| &moved[k]));
            let pose = LastStep::new(&solver, part(7) - part(0), before).pose;
            let l = (pose.r - r0).norm_squared() + (pose.t - t0).norm_squared();
            (l, pose, solver)
        };
        let (_, pose, solver) = loss(&x);
        let part = |c: usize| DVector::from_column_slice(&x[c * f..(c + 1) * f]);
        let last = LastStep::new(&solver, part(7) - part(0), before);
        let (ds, dtemplates) = last.backward(&((pose.r - r0) * 2.0), &((pose.t - t0) * 2.0));
        let analytic: Vec<f64> = dtemplates.iter().chain(ds.iter()).copied().collect();
        assert_eq!(analytic.len(), x.len());
        let h = 1e-6;
        for i in 0..x.len() {
            let mut up = x.clone();
            up[i] += h;
            let mut down = x.clone();
            down[i] -= h;
            let numeric = (loss(&up).0 - loss(&down).0) / (2.0 * h);
            assert!(
                (numeric - analytic[i]).abs()
                    <= 1e-5 * (1e-3 + numeric.abs().max(analytic[i].abs())),
                "feature entry {i}: numeric {numeric} analytic {}",
                analytic[i]
            );
        }
        assert!(analytic.iter().filter(|g| g.abs() > 1e-3).count() > x.len() / 2);
    }

    #[test]
    fn solves_a_linear_feature_model_exactly() {
        // phi(exp(xi) T) = phi(T) + J xi: one step recovers xi.
        let j = DMatrix::from_fn(10, 6, |i, k| {
            ((i * 7 + k * 3) % 5) as f64 - 2.0 + (i == k) as u8 as f64
        });
        let xi = DVector::from_vec(vec![0.01, -0.02, 0.03, 0.1, 0.0, -0.05]);
        let solver = LkSolver::new(j.clone());
        let step = solver.step(&(&j * &xi));
        for k in 0..6 {
            assert!((step[k] - xi[k]).abs() < 1e-5, "{step:?}");
        }
    }
}
