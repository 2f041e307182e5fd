//! Pose head output to a rigid transform, applying it to points, and their
//! backward passes.
//!
//! The head's raw output `[qw, qx, qy, qz, tx, ty, tz]` becomes
//! `R = rot(q / |q|)` and `t`, exactly as [`pcrnet_core::pose`] does
//! (the `qw >= 0` canonicalisation there does not change `R`, so training
//! skips it). The transform maps the source onto the template:
//! `p_template = R p_source + t`.

use pcrnet_core::pose::Rigid;

/// A 3x3 matrix, row-major.
pub type Mat3 = [[f32; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Rotation matrix of a unit quaternion `[w, x, y, z]`: the device's own
/// formula, [`pcrnet_core::Pose::rotation_matrix`].
pub fn quat_to_mat(q: [f32; 4]) -> Mat3 {
    pcrnet_core::Pose {
        rotation: q,
        translation: [0.0; 3],
    }
    .rotation_matrix()
}

/// `(R, t)` from a raw head output. A zero quaternion gives the identity
/// rotation (its gradient is then zero).
pub fn pose_from_raw(raw: &[f32]) -> (Mat3, [f32; 3]) {
    let q = [raw[0], raw[1], raw[2], raw[3]];
    let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt();
    let r = if n > 0.0 && n.is_finite() {
        quat_to_mat([q[0] / n, q[1] / n, q[2] / n, q[3] / n])
    } else {
        IDENTITY
    };
    (r, [raw[4], raw[5], raw[6]])
}

/// Backward of [`pose_from_raw`]: the gradient on the 7 raw outputs from the
/// gradients on `R` and `t`.
pub fn pose_from_raw_backward(raw: &[f32], dr: &Mat3, dt: &[f32; 3]) -> [f32; 7] {
    let q = [raw[0], raw[1], raw[2], raw[3]];
    let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt();
    let mut out = [0.0; 7];
    out[4..].copy_from_slice(dt);
    if !(n > 0.0 && n.is_finite()) {
        return out;
    }
    let [w, x, y, z] = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
    // dR/dw, dR/dx, dR/dy, dR/dz of the formula in `quat_to_mat`.
    let dw = [
        [0.0, -2.0 * z, 2.0 * y],
        [2.0 * z, 0.0, -2.0 * x],
        [-2.0 * y, 2.0 * x, 0.0],
    ];
    let dx = [
        [0.0, 2.0 * y, 2.0 * z],
        [2.0 * y, -4.0 * x, -2.0 * w],
        [2.0 * z, 2.0 * w, -4.0 * x],
    ];
    let dy = [
        [-4.0 * y, 2.0 * x, 2.0 * w],
        [2.0 * x, 0.0, 2.0 * z],
        [-2.0 * w, 2.0 * z, -4.0 * y],
    ];
    let dz = [
        [-4.0 * z, -2.0 * w, 2.0 * x],
        [2.0 * w, -4.0 * z, 2.0 * y],
        [2.0 * x, 2.0 * y, 0.0],
    ];
    let contract = |m: &Mat3| -> f32 {
        let mut s = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                s += m[i][j] * dr[i][j];
            }
        }
        s
    };
    let du = [contract(&dw), contract(&dx), contract(&dy), contract(&dz)];
    let u = [w, x, y, z];
    // Through u = q / |q|: dq = (du - u (u . du)) / |q|.
    let dot: f32 = u.iter().zip(&du).map(|(a, b)| a * b).sum();
    for k in 0..4 {
        out[k] = (du[k] - u[k] * dot) / n;
    }
    out
}

/// `R p + t` for every point.
pub fn transform_points(r: &Mat3, t: &[f32; 3], pts: &[[f32; 3]]) -> Vec<[f32; 3]> {
    pts.iter().map(|p| apply(r, t, p)).collect()
}

/// `R p + t`, by `pcrnet-core`'s [`Rigid::apply`] (the device's arithmetic).
pub fn apply(r: &Mat3, t: &[f32; 3], p: &[f32; 3]) -> [f32; 3] {
    Rigid {
        rotation: *r,
        translation: *t,
    }
    .apply(*p)
}

/// Backward of [`transform_points`] with respect to `R` and `t`, given the
/// gradient `dout` on the transformed points (sums in f64, in point order).
pub fn transform_points_backward(pts: &[[f32; 3]], dout: &[[f32; 3]]) -> (Mat3, [f32; 3]) {
    let mut dr = [[0f64; 3]; 3];
    let mut dt = [0f64; 3];
    for (p, g) in pts.iter().zip(dout) {
        for i in 0..3 {
            dt[i] += g[i] as f64;
            for j in 0..3 {
                dr[i][j] += g[i] as f64 * p[j] as f64;
            }
        }
    }
    (dr.map(|row| row.map(|v| v as f32)), dt.map(|v| v as f32))
}

/// Matrix product `a b`.
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// Transpose.
pub fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// `a v`.
pub fn mat_vec(a: &Mat3, v: &[f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

/// Composes `(r2, t2) after (r1, t1)`: `p -> r2 (r1 p + t1) + t2`.
pub fn compose(r2: &Mat3, t2: &[f32; 3], r1: &Mat3, t1: &[f32; 3]) -> (Mat3, [f32; 3]) {
    let r = mat_mul(r2, r1);
    let rt = mat_vec(r2, t1);
    (r, std::array::from_fn(|i| rt[i] + t2[i]))
}

/// The inverse rigid transform `(R^T, -R^T t)`.
pub fn invert(r: &Mat3, t: &[f32; 3]) -> (Mat3, [f32; 3]) {
    let rt = transpose(r);
    let v = mat_vec(&rt, t);
    (rt, v.map(|x| -x))
}

/// Rotation from Euler angles in radians, `R = Rz Ry Rx` (the convention of
/// [`crate::shapes::random_transform`]).
pub fn euler_to_mat(a: [f32; 3]) -> Mat3 {
    let (sx, cx, sy, cy, sz, cz) = (
        a[0].sin(),
        a[0].cos(),
        a[1].sin(),
        a[1].cos(),
        a[2].sin(),
        a[2].cos(),
    );
    [
        [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
        [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
        [-sy, cy * sx, cy * cx],
    ]
}

/// Rotation matrix to a unit quaternion `[w, x, y, z]` with `w >= 0`.
pub fn mat_to_quat(m: &Mat3) -> [f32; 4] {
    let m = m.map(|r| r.map(|v| v as f64));
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|v| (sign * v / n) as f32)
}
