//! Registration metrics: the one implementation used by training
//! validation, `pcrnet eval` and every experiment.
//!
//! - **Rotation error**: the angle of the axis-angle form of
//!   `R_est R_gt^T`, in degrees ([`rotation_error_deg`]).
//! - **Translation error**: `|t_est - t_gt|`, the L2 norm
//!   ([`translation_error`]), of the pose between the clouds as given (the
//!   pose a user gets), not of any internal centred frame.
//! - **Success ratio** at a rotation threshold: the fraction of
//!   registrations whose rotation error is at most the threshold. The
//!   **AUC** is the area under that curve from 0 to 180 degrees, sampled
//!   every [`AUC_STEP_DEG`] degrees and integrated by the trapezoid rule,
//!   divided by 180 (as the PCRNet paper defines it): 1 is perfect.
//! - **Success at (rotation, translation) criteria** ([`SUCCESS_CRITERIA`]):
//!   both errors at most their thresholds.
//! - Mean, median, standard deviation (population), minimum and maximum of
//!   each error and of the time per registration ([`Stats`]).

use serde::{Deserialize, Serialize};

use crate::geometry::Mat3;

/// Rotation error in degrees: the angle of the axis-angle form of
/// `M = R_est R_gt^T`, computed in f64 as
/// `atan2(|vee(M - M^T)| / 2, (trace(M) - 1) / 2)`. Unlike
/// `acos((trace(M) - 1) / 2)` this stays accurate near 0 (with f32 inputs
/// the `acos` form has a floor of about 0.02 degrees: a rotation compared
/// with itself did not score 0).
pub fn rotation_error_deg(r_est: &Mat3, r_gt: &Mat3) -> f64 {
    let m = error_rotation(r_est, r_gt);
    let tr = m[0][0] + m[1][1] + m[2][2];
    let axis = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]];
    let sin = 0.5 * axis.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cos = 0.5 * (tr - 1.0);
    sin.atan2(cos).to_degrees()
}

/// The error rotation `R_est R_gt^T` in f64: the turn that takes the true
/// rotation to the estimate, in the frame both map onto (the template's).
pub fn error_rotation(r_est: &Mat3, r_gt: &Mat3) -> [[f64; 3]; 3] {
    let mut m = [[0f64; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| r_est[i][k] as f64 * r_gt[j][k] as f64).sum();
        }
    }
    m
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

/// Step of the success-ratio curve and of the AUC integration, degrees.
pub const AUC_STEP_DEG: f64 = 0.5;

/// The (rotation degrees, translation) success criteria every summary reports.
pub const SUCCESS_CRITERIA: [(f64, f64); 3] = [(5.0, 0.05), (10.0, 0.1), (20.0, 0.2)];

/// Fraction of `rot_deg` at most `threshold` (0 for no registrations).
pub fn success_ratio(rot_deg: &[f64], threshold: f64) -> f64 {
    if rot_deg.is_empty() {
        return 0.0;
    }
    rot_deg.iter().filter(|&&e| e <= threshold).count() as f64 / rot_deg.len() as f64
}

/// The success-ratio curve: `(threshold, ratio)` for thresholds 0, 0.5, ...,
/// 180 degrees.
pub fn success_curve(rot_deg: &[f64]) -> Vec<(f64, f64)> {
    let mut sorted = rot_deg.to_vec();
    sorted.sort_by(f64::total_cmp);
    let steps = (180.0 / AUC_STEP_DEG).round() as usize;
    (0..=steps)
        .map(|i| {
            let th = i as f64 * AUC_STEP_DEG;
            let below = sorted.partition_point(|&e| e <= th);
            (th, below as f64 / sorted.len().max(1) as f64)
        })
        .collect()
}

/// Area under [`success_curve`] by the trapezoid rule, divided by 180.
pub fn auc(rot_deg: &[f64]) -> f64 {
    let curve = success_curve(rot_deg);
    let area: f64 = curve
        .windows(2)
        .map(|w| 0.5 * (w[0].1 + w[1].1) * (w[1].0 - w[0].0))
        .sum();
    area / 180.0
}

/// Mean, median, population standard deviation, minimum and maximum.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Stats {
    /// Arithmetic mean.
    pub mean: f64,
    /// Median (mean of the middle two for an even count).
    pub median: f64,
    /// Population standard deviation.
    pub std: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

impl Stats {
    /// Statistics of `v` (all zero when empty).
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return Stats::default();
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let n = s.len();
        let median = if n % 2 == 1 {
            s[n / 2]
        } else {
            (s[n / 2 - 1] + s[n / 2]) / 2.0
        };
        let mean = s.iter().sum::<f64>() / n as f64;
        let var = s.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        Stats {
            mean,
            median,
            std: var.sqrt(),
            min: s[0],
            max: s[n - 1],
        }
    }
}

/// Success at one (rotation, translation) criterion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Success {
    /// Rotation threshold, degrees.
    pub rot_deg: f64,
    /// Translation threshold.
    pub trans: f64,
    /// Fraction of registrations within both.
    pub ratio: f64,
}

/// Summary of a set of registrations.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Summary {
    /// Number of registrations.
    pub count: usize,
    /// Rotation error, degrees.
    pub rotation_deg: Stats,
    /// Translation error.
    pub translation: Stats,
    /// Time per registration in milliseconds, when measured.
    pub time_ms: Option<Stats>,
    /// Area under the success-ratio curve (0 to 180 degrees, / 180).
    pub auc: f64,
    /// Success at each of [`SUCCESS_CRITERIA`].
    pub success: Vec<Success>,
}

impl Summary {
    /// Summarises per-registration rotation errors (degrees), translation
    /// errors and, optionally, times (seconds).
    pub fn of(rot_deg: &[f64], trans: &[f64], seconds: Option<&[f64]>) -> Self {
        let success = SUCCESS_CRITERIA
            .iter()
            .map(|&(r, t)| Success {
                rot_deg: r,
                trans: t,
                ratio: if rot_deg.is_empty() {
                    0.0
                } else {
                    rot_deg
                        .iter()
                        .zip(trans)
                        .filter(|&(&e, &d)| e <= r && d <= t)
                        .count() as f64
                        / rot_deg.len() as f64
                },
            })
            .collect();
        Summary {
            count: rot_deg.len(),
            rotation_deg: Stats::of(rot_deg),
            translation: Stats::of(trans),
            time_ms: seconds.map(|s| Stats::of(&s.iter().map(|x| x * 1e3).collect::<Vec<_>>())),
            auc: auc(rot_deg),
            success,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{IDENTITY, euler_to_mat};

    #[test]
    fn known_angles() {
        assert!(rotation_error_deg(&IDENTITY, &IDENTITY) < 1e-3);
        let r = euler_to_mat([0.0, 0.0, 30f32.to_radians()]);
        assert!((rotation_error_deg(&r, &IDENTITY) - 30.0).abs() < 1e-3);
        // Accurate near 0 and near 180 degrees, and symmetric.
        let a = euler_to_mat([0.3, -0.7, 1.1]);
        assert!(rotation_error_deg(&a, &a) < 1e-4);
        let b = crate::geometry::mat_mul(&euler_to_mat([0.0, 0.0, 1e-3]), &a);
        assert!((rotation_error_deg(&b, &a) - 1e-3f64.to_degrees()).abs() < 1e-3);
        assert!((rotation_error_deg(&a, &b) - rotation_error_deg(&b, &a)).abs() < 1e-9);
        let flip = euler_to_mat([std::f32::consts::PI, 0.0, 0.0]);
        assert!((rotation_error_deg(&flip, &IDENTITY) - 180.0).abs() < 1e-3);
        assert!((translation_error(&[1.0, 2.0, 2.0], &[0.0; 3]) - 3.0).abs() < 1e-9);
    }

    #[test]
    fn statistics() {
        let s = Stats::of(&[1.0, 3.0, 2.0, 10.0]);
        assert_eq!((s.median, s.mean, s.min, s.max), (2.5, 4.0, 1.0, 10.0));
        assert!((s.std - 12.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(Stats::of(&[]), Stats::default());
    }

    #[test]
    fn auc_and_success() {
        // Perfect registrations: the curve is 1 everywhere.
        assert!((auc(&[0.0; 4]) - 1.0).abs() < 1e-12);
        // All at 180 degrees: 0 up to 179.5, 1 at 180 -> one half-step triangle.
        assert!((auc(&[180.0; 3]) - 0.25 / 180.0).abs() < 1e-12);
        // Errors uniform on a fine grid over [0, 180] give about 1/2.
        let uniform: Vec<f64> = (0..=3600).map(|i| i as f64 * 0.05).collect();
        assert!((auc(&uniform) - 0.5).abs() < 2e-3);
        // A single error of 90 degrees: success 0 below 90, 1 from 90 on;
        // the trapezoid adds a quarter degree at the step.
        assert!((auc(&[90.0]) - 90.25 / 180.0).abs() < 1e-12);
        assert_eq!(success_ratio(&[1.0, 5.0, 6.0, 30.0], 5.0), 0.5);
        let curve = success_curve(&[1.0, 5.0]);
        assert_eq!(curve.len(), 361);
        assert_eq!(curve[2], (1.0, 0.5));
        assert_eq!(curve[10], (5.0, 1.0));
        let s = Summary::of(
            &[1.0, 4.0, 9.0, 50.0],
            &[0.01, 0.2, 0.05, 0.0],
            Some(&[0.002; 4]),
        );
        let ratios: Vec<f64> = s.success.iter().map(|x| x.ratio).collect();
        assert_eq!(ratios, vec![0.25, 0.5, 0.75]);
        assert!((s.time_ms.unwrap().mean - 2.0).abs() < 1e-12);
        assert_eq!(s.count, 4);
    }
}

/// How well a confidence score separates good registrations from bad ones.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Confidence {
    /// Registrations counted good (rotation error below [`Confidence::good_below_deg`]).
    pub good: usize,
    /// The others.
    pub bad: usize,
    /// The rotation error (degrees) below which a registration is good.
    pub good_below_deg: f64,
    /// Area under the ROC curve of "residual ranks good below bad": the
    /// probability that a random good registration has a lower residual
    /// than a random bad one (ties count half). `None` without both kinds.
    pub auroc: Option<f64>,
    /// Share of bad registrations flagged unreliable.
    pub bad_flagged: f64,
    /// Share of good registrations flagged unreliable (false alarms).
    pub good_flagged: f64,
    /// Share of registrations flagged reliable that are bad.
    pub reliable_but_bad: f64,
}

impl Confidence {
    /// From per-registration rotation errors, residuals and reliability flags.
    pub fn of(rot_deg: &[f64], residual: &[f64], reliable: &[bool], good_below_deg: f64) -> Self {
        let good: Vec<f64> = rot_deg
            .iter()
            .zip(residual)
            .filter(|(e, _)| **e < good_below_deg)
            .map(|(_, r)| *r)
            .collect();
        let bad: Vec<f64> = rot_deg
            .iter()
            .zip(residual)
            .filter(|(e, _)| **e >= good_below_deg)
            .map(|(_, r)| *r)
            .collect();
        let auroc = (!good.is_empty() && !bad.is_empty()).then(|| {
            let mut wins = 0.0;
            for g in &good {
                for b in &bad {
                    wins += if g < b {
                        1.0
                    } else if g == b {
                        0.5
                    } else {
                        0.0
                    };
                }
            }
            wins / (good.len() * bad.len()) as f64
        });
        let share = |num: usize, den: usize| {
            if den == 0 {
                0.0
            } else {
                num as f64 / den as f64
            }
        };
        let flagged = |want_good: bool| {
            rot_deg
                .iter()
                .zip(reliable)
                .filter(|(e, r)| (**e < good_below_deg) == want_good && !**r)
                .count()
        };
        let reliable_count = reliable.iter().filter(|r| **r).count();
        let reliable_bad = rot_deg
            .iter()
            .zip(reliable)
            .filter(|(e, r)| **e >= good_below_deg && **r)
            .count();
        Confidence {
            good: good.len(),
            bad: bad.len(),
            good_below_deg,
            auroc,
            bad_flagged: share(flagged(false), bad.len()),
            good_flagged: share(flagged(true), good.len()),
            reliable_but_bad: share(reliable_bad, reliable_count),
        }
    }
}

#[cfg(test)]
mod confidence_tests {
    use super::*;

    #[test]
    fn auroc_and_flag_rates() {
        // Good: errors 1, 2 with residuals 0.1, 0.3; bad: 40, 90 with 0.2, 0.5.
        let c = Confidence::of(
            &[1.0, 40.0, 2.0, 90.0],
            &[0.1, 0.2, 0.3, 0.5],
            &[true, true, false, false],
            5.0,
        );
        assert_eq!((c.good, c.bad), (2, 2));
        // Pairs (g, b): (0.1,0.2) (0.1,0.5) (0.3,0.5) won, (0.3,0.2) lost.
        assert_eq!(c.auroc, Some(0.75));
        assert_eq!(
            (c.bad_flagged, c.good_flagged, c.reliable_but_bad),
            (0.5, 0.5, 0.5)
        );
        assert_eq!(Confidence::of(&[1.0], &[0.1], &[true], 5.0).auroc, None);
    }
}
