//! Losses and their gradients.
//!
//! - **Chamfer** (default, as PCRNet): `mean_i min_j |a_i - b_j|^2 +
//!   mean_j min_i |a_i - b_j|^2` between the template `a` and the
//!   transformed source `b`; the gradient is taken with respect to `b` only
//!   (the template is data). Nearest neighbours by brute force, ties to the
//!   first index.
//! - **Pose** (Frobenius): `|R_est - R_gt|_F^2 + |t_est - t_gt|^2`, the
//!   squared Frobenius norm of the difference of the 4x4 matrices.

use serde::{Deserialize, Serialize};

use super::geometry::Mat3;

/// Which loss drives training.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum LossKind {
    /// Chamfer distance between the template and the registered source.
    Chamfer,
    /// Squared Frobenius distance between estimated and true 4x4 poses.
    Pose,
}

/// Index of the nearest point of `b` to `p` (squared distance too).
fn nearest(p: &[f32; 3], b: &[[f32; 3]]) -> (usize, f32) {
    let mut best = (0usize, f32::INFINITY);
    for (j, q) in b.iter().enumerate() {
        let d = (p[0] - q[0]) * (p[0] - q[0])
            + (p[1] - q[1]) * (p[1] - q[1])
            + (p[2] - q[2]) * (p[2] - q[2]);
        if d < best.1 {
            best = (j, d);
        }
    }
    best
}

/// Chamfer loss between `a` (template) and `b` (registered source) and its
/// gradient with respect to `b`. Sums in f64, in index order.
pub fn chamfer(a: &[[f32; 3]], b: &[[f32; 3]]) -> (f32, Vec<[f32; 3]>) {
    let mut db = vec![[0f32; 3]; b.len()];
    if a.is_empty() || b.is_empty() {
        return (0.0, db);
    }
    let (na, nb) = (a.len() as f32, b.len() as f32);
    let mut sum_a = 0f64;
    for p in a {
        let (j, d) = nearest(p, b);
        sum_a += d as f64;
        for k in 0..3 {
            db[j][k] += 2.0 * (b[j][k] - p[k]) / na;
        }
    }
    let mut sum_b = 0f64;
    for (j, q) in b.iter().enumerate() {
        let (i, d) = nearest(q, a);
        sum_b += d as f64;
        for k in 0..3 {
            db[j][k] += 2.0 * (q[k] - a[i][k]) / nb;
        }
    }
    ((sum_a / na as f64 + sum_b / nb as f64) as f32, db)
}

/// Chamfer loss only (no gradient).
pub fn chamfer_value(a: &[[f32; 3]], b: &[[f32; 3]]) -> f32 {
    if a.is_empty() || b.is_empty() {
        return 0.0;
    }
    let sa: f64 = a.iter().map(|p| nearest(p, b).1 as f64).sum();
    let sb: f64 = b.iter().map(|q| nearest(q, a).1 as f64).sum();
    (sa / a.len() as f64 + sb / b.len() as f64) as f32
}

/// Frobenius pose loss and its gradients with respect to `r` and `t`.
pub fn pose_loss(r: &Mat3, t: &[f32; 3], r_gt: &Mat3, t_gt: &[f32; 3]) -> (f32, Mat3, [f32; 3]) {
    let mut loss = 0f64;
    let mut dr = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let d = r[i][j] - r_gt[i][j];
            loss += (d as f64) * (d as f64);
            dr[i][j] = 2.0 * d;
        }
    }
    let mut dt = [0f32; 3];
    for i in 0..3 {
        let d = t[i] - t_gt[i];
        loss += (d as f64) * (d as f64);
        dt[i] = 2.0 * d;
    }
    (loss as f32, dr, dt)
}
