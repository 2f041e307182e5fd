//! Registration error metrics, shared by validation and evaluation.

use super::geometry::Mat3;

/// Rotation error in degrees: the angle of the axis-angle form of
/// `M = R_est R_gt^T`, computed in f64 as
/// `atan2(|vee(M - M^T)| / 2, (trace(M) - 1) / 2)`. Unlike
/// `acos((trace(M) - 1) / 2)` this stays accurate near 0 (with f32 inputs
/// the `acos` form has a floor of about 0.02 degrees: a rotation compared
/// with itself did not score 0).
pub fn rotation_error_deg(r_est: &Mat3, r_gt: &Mat3) -> f64 {
    let mut m = [[0f64; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| r_est[i][k] as f64 * r_gt[j][k] as f64).sum();
        }
    }
    let tr = m[0][0] + m[1][1] + m[2][2];
    let axis = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]];
    let sin = 0.5 * axis.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cos = 0.5 * (tr - 1.0);
    sin.atan2(cos).to_degrees()
}

/// Translation error: the Euclidean norm of `t_est - t_gt`, in f64.
pub fn translation_error(t_est: &[f32; 3], t_gt: &[f32; 3]) -> f64 {
    t_est
        .iter()
        .zip(t_gt)
        .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Summary of errors over a set of registrations.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct ErrorSummary {
    /// Number of registrations.
    pub count: usize,
    /// Mean rotation error (degrees).
    pub rot_mean_deg: f64,
    /// Median rotation error (degrees).
    pub rot_median_deg: f64,
    /// Mean translation error.
    pub trans_mean: f64,
    /// Median translation error.
    pub trans_median: f64,
}

impl ErrorSummary {
    /// Summarises per-registration rotation (degrees) and translation errors.
    pub fn from_errors(rot: &[f64], trans: &[f64]) -> Self {
        let median = |v: &[f64]| -> f64 {
            if v.is_empty() {
                return 0.0;
            }
            let mut s = v.to_vec();
            s.sort_by(f64::total_cmp);
            let m = s.len() / 2;
            if s.len() % 2 == 1 {
                s[m]
            } else {
                (s[m - 1] + s[m]) / 2.0
            }
        };
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        ErrorSummary {
            count: rot.len(),
            rot_mean_deg: mean(rot),
            rot_median_deg: median(rot),
            trans_mean: mean(trans),
            trans_median: median(trans),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::geometry::{IDENTITY, euler_to_mat};

    #[test]
    fn known_angles() {
        assert!(rotation_error_deg(&IDENTITY, &IDENTITY) < 1e-3);
        let r = euler_to_mat([0.0, 0.0, 30f32.to_radians()]);
        assert!((rotation_error_deg(&r, &IDENTITY) - 30.0).abs() < 1e-3);
        // Accurate near 0 and near 180 degrees, and symmetric.
        let a = euler_to_mat([0.3, -0.7, 1.1]);
        assert!(rotation_error_deg(&a, &a) < 1e-4);
        let b = crate::train::geometry::mat_mul(&euler_to_mat([0.0, 0.0, 1e-3]), &a);
        assert!((rotation_error_deg(&b, &a) - 1e-3f64.to_degrees()).abs() < 1e-3);
        assert!((rotation_error_deg(&a, &b) - rotation_error_deg(&b, &a)).abs() < 1e-9);
        let flip = euler_to_mat([std::f32::consts::PI, 0.0, 0.0]);
        assert!((rotation_error_deg(&flip, &IDENTITY) - 180.0).abs() < 1e-3);
        assert!((translation_error(&[1.0, 2.0, 2.0], &[0.0; 3]) - 3.0).abs() < 1e-9);
        let s = ErrorSummary::from_errors(&[1.0, 3.0, 2.0, 10.0], &[0.0, 1.0, 1.0, 1.0]);
        assert_eq!(s.rot_median_deg, 2.5);
        assert_eq!(s.rot_mean_deg, 4.0);
    }
}
