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
//! from 0.003 to 0.028 of the size. A template whose floor is near or above
//! 0.015 has its right poses marked not reliable; in that experiment those
//! templates were most of the frames lost.
//!
//! [`residual_floor`] measures it on the host, where the object's other
//! points are at hand: the points of the object the template did not store,
//! scored at the template's own pose with no noise. The exporter stores it
//! in the blob (format 6, `Trailer::residual_floor`; `Reference::new`
//! measures it on the template file's points beyond those stored), and
//! `pcrnet_core::registration::max_residual_for` turns it into the
//! verdict threshold of the blob's recommended options.

use pcrnet_core::refine::{MAX_SUBSET, Subset, score};
use pcrnet_core::template::Template;
use pcrnet_core::{Frame, Pose};

/// The relative plane residual of `others` (user units: the object's
/// points that `template` did not store; `frame` maps user units to the
/// model frame) at the template's own pose, each point's distance capped
/// at `inlier_distance` (model units) as a registration's residual is:
/// what a perfect, noiseless pose of a view of the object scores at best.
/// At most [`MAX_SUBSET`] points are scored (every k-th). `None` when
/// `others` is empty or holds a non-finite point.
pub fn residual_floor(
    template: &Template<'_>,
    frame: &Frame,
    others: &[[f32; 3]],
    inlier_distance: f32,
) -> Option<f32> {
    if others.is_empty() || others.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let subset = Subset::new(others, *frame, MAX_SUBSET);
    let at_rest = frame.pose_to_model(&Pose::IDENTITY);
    let fit = score(template, &subset, &at_rest, inlier_distance);
    Some(fit.plane_residual).filter(|r| r.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Shape, sample};
    use crate::template::bind;
    use pcrnet_core::registration::{NOISE_ALLOWANCE, max_residual_for};
    use pcrnet_core::{Int8Model, Options};
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
            let floor = residual_floor(
                model.template(),
                model.frame(),
                others,
                options.inlier_distance,
            )
            .unwrap();
            // The blob carries the floor of the template file's points left
            // out (`stored` beyond `n`), and its options are calibrated by it.
            let carried = model.residual_floor().unwrap();
            assert_eq!(
                model.trained_options().max_residual,
                max_residual_for(carried, 0.015)
            );
            (floor, carried)
        };
        let ((dense, _), (sparse, carried)) = (floor(1024), floor(64));
        // The same surface at the same density, other points: close.
        assert!(
            (carried - sparse).abs() < 0.25 * sparse,
            "{carried} vs {sparse}"
        );
        // The same in other units and place: the floor is a share of the
        // template's size, measured in its own frame.
        let moved = |c: &[[f32; 3]]| -> Vec<[f32; 3]> {
            c.iter().map(|p| p.map(|v| v * 3.0 + 100.0)).collect()
        };
        let bound = bind(&blob, &moved(stored), 64).unwrap();
        let model = Int8Model::from_bytes(&bound).unwrap();
        let far = residual_floor(model.template(), model.frame(), &moved(others), 0.05).unwrap();
        assert!(
            (far - sparse).abs() < 1e-3 * sparse.max(1e-3) + 2e-4,
            "{far} vs {sparse}"
        );
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
        let floor =
            |others: &[[f32; 3]]| residual_floor(model.template(), model.frame(), others, 0.05);
        assert_eq!(floor(&[]), None);
        assert_eq!(floor(&[[0.0, f32::NAN, 0.0]]), None);
    }
}
