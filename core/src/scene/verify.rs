//! Verification against the frame: does a pose explain what the sensor saw?
//!
//! The template's stored points are moved into the sensor frame by the
//! inverse of the pose and projected into the frame ([`Intrinsics`]). At
//! each point's pixel the frame's observed depth `z_o` is compared with the
//! point's own `z`:
//!
//! - `|z - z_o| <= tolerance`: **supported**, the sensor saw the surface there;
//! - `z < z_o - tolerance`: **free-space violation**, the sensor saw
//!   *through* where the object would be, so the object cannot be there;
//! - `z > z_o + tolerance`: **occluded**, behind what the sensor saw (the
//!   object's own far side, or something in front of it): no evidence;
//! - no depth at the pixel, or outside the frame: **unobserved**.
//!
//! A pose passes when the violations are at most `max_violation` of the
//! points the sensor could judge (supported + violations) and the
//! supported points are at least `min_support` of the points with an
//! observation. A fragment of another object registered onto part of the
//! template fails: the rest of the template would float in free space.
//! This is the free-space and support test of model-based verification
//! (e.g. Aldoma et al., *A Global Hypotheses Verification Method for 3D
//! Object Recognition*, ECCV 2012), reduced to the template's points
//! without normals: a back-facing point is judged by depth alone, and it
//! is behind the front surface when the pose is right.

use super::depth::{Intrinsics, Organised, project};
use crate::format::Frame;
use crate::pose::Pose;
use crate::template::Template;

/// What [`verify`] counts, and its verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Verification {
    /// Template points whose depth the sensor saw at their place.
    pub supported: u32,
    /// Template points in front of what the sensor saw (free space).
    pub violations: u32,
    /// Template points behind what the sensor saw.
    pub occluded: u32,
    /// Template points outside the frame or at a pixel without depth.
    pub unobserved: u32,
    /// Violations and support within the settings' bounds.
    pub passed: bool,
}

/// How [`verify`] judges.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VerifySettings {
    /// Depth agreement, user units.
    pub tolerance: f32,
    /// Most violations, as a share of supported + violations.
    pub max_violation: f32,
    /// Least support, as a share of the points with an observation.
    pub min_support: f32,
}

impl VerifySettings {
    /// For an object of `radius` user units (its points' largest distance
    /// from their mean): depth within 6% of the radius (about the
    /// residual's inlier distance, 5% of the object's longest side), at
    /// most 10% violations, at least 20% support.
    pub fn for_object(radius: f32) -> Self {
        VerifySettings {
            tolerance: 0.06 * radius,
            max_violation: 0.1,
            min_support: 0.2,
        }
    }
}

/// Checks `pose` (mapping sensor-frame points onto the template, user
/// units) against `frame` seen with `intrinsics`: every stored template
/// point in `template` (model frame `model`) is moved into the sensor frame
/// and compared with the depth seen at its pixel.
pub fn verify<F: Organised>(
    frame: &F,
    intrinsics: &Intrinsics,
    template: &Template,
    model: &Frame,
    pose: &Pose,
    settings: &VerifySettings,
) -> Verification {
    let back = pose.inverse();
    let mut v = Verification {
        supported: 0,
        violations: 0,
        occluded: 0,
        unobserved: 0,
        passed: false,
    };
    for i in 0..template.len() {
        let p = back.transform_point(template.user_point(i, model));
        let observed = project(intrinsics, p).and_then(|([u, v], _)| {
            let (u, v) = (libm::roundf(u), libm::roundf(v));
            if u < 0.0 || v < 0.0 {
                return None;
            }
            frame.point(u as usize, v as usize)
        });
        let Some(o) = observed else {
            v.unobserved += 1;
            continue;
        };
        let gap = p[2] - o[2];
        if gap < -settings.tolerance {
            v.violations += 1;
        } else if gap > settings.tolerance {
            v.occluded += 1;
        } else {
            v.supported += 1;
        }
    }
    let judged = (v.supported + v.violations) as f32;
    let observed = (v.supported + v.violations + v.occluded) as f32;
    v.passed = v.supported > 0
        && v.violations as f32 <= settings.max_violation * judged
        && v.supported as f32 >= settings.min_support * observed;
    v
}
