//! The verdict's calibration for one template: its **residual floor**.
//!
//! A registration is reliable when its relative plane residual (the mean
//! distance from the moved source's points to the tangent planes of their
//! nearest template points, a share of the template's size) is at most
//! `Options::max_residual`, 0.015 by default. A right pose scores the
//! sensor's noise plus what the template's stored points cannot represent:
//! edges and thin parts between sparse samples, inner surfaces a mesh
//! sampler put points on, normals estimated across a fold. That second
//! part, the floor, is a property of the template, and it varies: over the
//! `tracking` experiment's twenty ModelNet10 templates (512 stored points)
//! from 0.003 to 0.030 of the size. A template whose floor is near or above
//! 0.015 has its right poses marked not reliable; in that experiment those
//! templates were most of the frames lost.
//!
//! [`residual_floor`] measures it on the host, where the object's other
//! points are at hand: the points of the object the template did not store,
//! scored at the template's own pose with no noise. [`max_residual_for`]
//! turns it into a verdict threshold for that template.

use pcrnet_core::refine::{MAX_SUBSET, Subset, score};
use pcrnet_core::{Int8Model, Options, Pose};

/// What [`max_residual_for`] allows above the floor for the sensor's
/// noise, a share of the template's size: the mean distance of Gaussian
/// noise of sigma 0.01 per coordinate from a plane, `0.01 sqrt(2 / pi)`,
/// the noise of the `trust` and `tracking` experiments. (The default
/// threshold, 0.015, is this plus a floor of 0.007.)
pub const NOISE_ALLOWANCE: f32 = 0.008;

/// The relative plane residual of `others` (user units: the object's
/// points that the template of `model` did not store) at the template's
/// own pose, each point's distance capped at `options.inlier_distance`
/// as a registration's residual is: what a perfect, noiseless pose of a
/// view of the object scores at best. At most [`MAX_SUBSET`] points are
/// scored (every k-th). `None` when `others` is empty or holds a
/// non-finite point.
pub fn residual_floor(
    model: &Int8Model<'_>,
    others: &[[f32; 3]],
    options: &Options,
) -> Option<f32> {
    if others.is_empty() || others.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let frame = *model.frame();
    let subset = Subset::new(others, frame, MAX_SUBSET);
    let at_rest = frame.pose_to_model(&Pose::IDENTITY);
    let fit = score(model.template(), &subset, &at_rest, options.inlier_distance);
    Some(fit.plane_residual).filter(|r| r.is_finite())
}

/// The verdict threshold (`Options::max_residual`) for a template whose
/// [`residual_floor`] is `floor`: its floor plus [`NOISE_ALLOWANCE`], and
/// never below `default` (the options' own threshold): a well-sampled
/// template keeps the default verdict, a sparse or folded one gets room
/// for its right poses. Measured on the `tracking` experiment (RESULTS.md):
/// the frames lost fall from about 18-20% to 0.2-2.3%, and more of the
/// reliable frames are 5-30 degrees off (a template that represents its
/// object coarsely also aligns it coarsely).
pub fn max_residual_for(floor: f32, default: f32) -> f32 {
    (floor + NOISE_ALLOWANCE).max(default)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Shape, sample};
    use crate::template::bind;
    use std::path::PathBuf;

    fn shipped() -> Vec<u8> {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../models/embedded-default-int8.pcrn");
        std::fs::read(path).unwrap()
    }

    #[test]
    fn a_sparser_template_has_a_higher_floor() {
        let blob = shipped();
        let cloud = sample(Shape::Box, 4096, 3);
        let (stored, others) = cloud.split_at(2048);
        let options = Options::default();
        let floor = |n: usize| {
            let bound = bind(&blob, stored, n).unwrap();
            let model = Int8Model::from_bytes(&bound).unwrap();
            residual_floor(&model, others, &options).unwrap()
        };
        let (dense, sparse) = (floor(1024), floor(64));
        // A box's faces are planes: a dense template represents them to
        // the quantisation step; 64 points leave edges to wrong planes.
        assert!(dense < 0.005, "{dense}");
        assert!(sparse > 2.0 * dense, "{sparse} vs {dense}");
        assert_eq!(max_residual_for(dense, 0.015), 0.015);
        assert_eq!(max_residual_for(0.02, 0.015), 0.02 + NOISE_ALLOWANCE);
    }

    #[test]
    fn no_points_or_non_finite_ones_have_no_floor() {
        let blob = shipped();
        let model = Int8Model::from_bytes(&blob).unwrap();
        let options = Options::default();
        assert_eq!(residual_floor(&model, &[], &options), None);
        assert_eq!(
            residual_floor(&model, &[[0.0, f32::NAN, 0.0]], &options),
            None
        );
    }
}
