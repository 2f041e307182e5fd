//! Scoring a pose up to the shape's symmetry (issue 36): the
//! symmetry-aware error, ADD-S, beside the plain rotation error, and
//! whether the ambiguity a registration reported explains its error.

use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use nalgebra::{Matrix3, Vector3};
use pcrnet_core::{Ambiguity, Pose};
use pcrnet_train::geometry::Mat3;
use pcrnet_train::metrics;

use crate::GOOD_BELOW_DEG;

/// A free axis explains a pose's error when the error rotation's axis lies
/// within this cosine of it (about 18 degrees).
pub const AXIS_MATCH_COS: f64 = 0.95;

/// ADD-S (Hinterstoisser et al., 2012; the BOP benchmark's symmetric
/// distance): the template moved by the inverse of `est` and of `truth`
/// (into the source's frame), the mean distance from each truth-moved point
/// to the nearest est-moved point. A turn about a symmetry of the shape
/// costs nothing; the units are the template's.
pub fn add_s(est: &Pose, truth: &Pose, template: &[[f32; 3]]) -> f64 {
    let (e, t) = (est.inverse(), truth.inverse());
    let moved: Vec<[f64; 3]> = template
        .iter()
        .map(|&p| e.transform_point(p).map(f64::from))
        .collect();
    let tree: ImmutableKdTree<f64, u32, 3, 16> = ImmutableKdTree::new_from_slice(&moved);
    let total: f64 = template
        .iter()
        .map(|&p| {
            let q = t.transform_point(p).map(f64::from);
            tree.nearest_one::<SquaredEuclidean>(&q).distance.sqrt()
        })
        .sum();
    total / template.len().max(1) as f64
}

/// The template's diameter as ADD-S is judged against: twice the largest
/// distance of a point from the centroid (at least the smallest positive f64).
pub fn diameter(template: &[[f32; 3]]) -> f64 {
    let n = template.len().max(1) as f64;
    let c: [f64; 3] =
        std::array::from_fn(|k| template.iter().map(|p| f64::from(p[k])).sum::<f64>() / n);
    let far = template
        .iter()
        .map(|p| {
            (0..3)
                .map(|k| (f64::from(p[k]) - c[k]).powi(2))
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
        .sqrt();
    (2.0 * far).max(f64::MIN_POSITIVE)
}

/// The true pose of a pair as a [`Pose`].
pub fn truth(r_gt: &Mat3, t_gt: &[f32; 3]) -> Pose {
    let r = Matrix3::from_fn(|i, j| f64::from(r_gt[i][j]));
    let t = Vector3::from_fn(|i, _| f64::from(t_gt[i]));
    crate::pose_from_matrix(&r, &t)
}

/// Whether `ambiguity` explains the error of `est` against the true
/// rotation `r_gt`: its turn leads to a pose within the success angle of
/// the truth, or the error rotation (template frame) turns about its free
/// axis ([`AXIS_MATCH_COS`]).
pub fn explains(ambiguity: &Ambiguity, est: &Pose, r_gt: &Mat3) -> bool {
    let turn_explains = ambiguity.turn.is_some_and(|t| {
        let other = est.then(&t.motion);
        metrics::rotation_error_deg(&other.rotation_matrix(), r_gt) < GOOD_BELOW_DEG
    });
    let axis_explains = ambiguity.axis.is_some_and(|a| {
        // The error rotation, a motion of the template's frame.
        let m = metrics::error_rotation(&est.rotation_matrix(), r_gt);
        let axis = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]];
        let norm = axis.iter().map(|v| v * v).sum::<f64>().sqrt();
        let dot: f64 = (0..3).map(|k| axis[k] * f64::from(a.direction[k])).sum();
        // A half turn has no skew part to read the axis from: count it as
        // explained only through the turn.
        norm > 1e-9 && (dot / norm).abs() >= AXIS_MATCH_COS
    });
    turn_explains || axis_explains
}

#[cfg(test)]
mod tests {
    use super::*;

    fn about_z(deg: f32) -> Pose {
        let h = deg.to_radians() / 2.0;
        Pose {
            rotation: [h.cos(), 0.0, 0.0, h.sin()],
            translation: [0.0; 3],
        }
    }

    #[test]
    fn a_turn_about_a_symmetry_costs_nothing() {
        // A ring about z: any turn about z maps it onto itself.
        let ring: Vec<[f32; 3]> = (0..360)
            .map(|i| {
                let a = (i as f32).to_radians();
                [a.cos(), a.sin(), 0.0]
            })
            .collect();
        let off = add_s(&about_z(40.0), &Pose::IDENTITY, &ring);
        assert!(off < 0.01, "{off}");
        // An "L" is not symmetric about z.
        let ell: Vec<[f32; 3]> = (0..100)
            .map(|i| [i as f32 / 100.0, 0.0, 0.0])
            .chain((0..50).map(|i| [0.0, i as f32 / 100.0, 0.0]))
            .collect();
        assert!(add_s(&about_z(40.0), &Pose::IDENTITY, &ell) > 0.1);
        assert!((diameter(&ring) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn an_axis_or_a_turn_explains_the_error_it_names() {
        let truth = Pose::IDENTITY.rotation_matrix();
        let est = about_z(60.0);
        let axis = |direction| Ambiguity {
            axis: Some(pcrnet_core::FreeAxis {
                direction,
                point: [0.0; 3],
                stiffness: 0.0,
            }),
            turn: None,
        };
        assert!(explains(&axis([0.0, 0.0, 1.0]), &est, &truth));
        assert!(!explains(&axis([1.0, 0.0, 0.0]), &est, &truth));
        let turn = |motion| Ambiguity {
            axis: None,
            turn: Some(pcrnet_core::Turn {
                motion,
                degrees: 60.0,
                relative_plane_residual: 0.0,
            }),
        };
        assert!(explains(&turn(about_z(-60.0)), &est, &truth));
        assert!(!explains(&turn(about_z(60.0)), &est, &truth));
    }
}
