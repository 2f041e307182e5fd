//! Registration error metrics, shared by validation and evaluation.

use super::geometry::Mat3;

/// Rotation error in degrees: the angle of the axis-angle form of
/// `R_est R_gt^T`, i.e. `acos((trace(R_est R_gt^T) - 1) / 2)`, in f64, with
/// the cosine clamped to `[-1, 1]`.
pub fn rotation_error_deg(r_est: &Mat3, r_gt: &Mat3) -> f64 {
    // trace(A B^T) = sum_ij A_ij B_ij
    let mut tr = 0f64;
    for i in 0..3 {
        for j in 0..3 {
            tr += r_est[i][j] as f64 * r_gt[i][j] as f64;
        }
    }
    ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
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
        assert!((translation_error(&[1.0, 2.0, 2.0], &[0.0; 3]) - 3.0).abs() < 1e-9);
        let s = ErrorSummary::from_errors(&[1.0, 3.0, 2.0, 10.0], &[0.0, 1.0, 1.0, 1.0]);
        assert_eq!(s.rot_median_deg, 2.5);
        assert_eq!(s.rot_mean_deg, 4.0);
    }
}
