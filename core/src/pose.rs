//! From the 7 head outputs to a rigid transform.
//!
//! The head outputs `[qw, qx, qy, qz, tx, ty, tz]`. The quaternion is
//! normalised by its Euclidean norm (`libm::sqrtf`) and made canonical with
//! `qw >= 0` (q and -q are the same rotation). The pose maps the **source
//! onto the template**: `p_template ~= R p_source + t`.
//!
//! All of this is f32 arithmetic with single IEEE-754 operations (no fused
//! multiply-add: Rust never contracts) and `libm` called explicitly, so the
//! result is bit-identical on x86_64 and thumbv7em.

use crate::arch::POSE_DIM;
use crate::error::{Error, Result};

/// A rigid transform: unit quaternion (scalar first) and translation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose {
    /// Unit quaternion `[w, x, y, z]` with `w >= 0`.
    pub rotation: [f32; 4],
    /// Translation `[x, y, z]`.
    pub translation: [f32; 3],
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Pose = Pose {
        rotation: [1.0, 0.0, 0.0, 0.0],
        translation: [0.0; 3],
    };

    /// Builds a pose from raw head outputs `[qw, qx, qy, qz, tx, ty, tz]`.
    ///
    /// Fails with [`Error::DegeneratePose`] when the quaternion's norm is not
    /// a positive finite number or a translation is not finite.
    pub fn from_head_output(raw: &[f32; POSE_DIM]) -> Result<Pose> {
        let [w, x, y, z, tx, ty, tz] = *raw;
        let n = libm::sqrtf(w * w + x * x + y * y + z * z);
        if !(n.is_finite() && n > 0.0 && tx.is_finite() && ty.is_finite() && tz.is_finite()) {
            return Err(Error::DegeneratePose);
        }
        let s = if w < 0.0 { -1.0 / n } else { 1.0 / n };
        Ok(Pose {
            rotation: [w * s, x * s, y * s, z * s],
            translation: [tx, ty, tz],
        })
    }

    /// The 3x3 rotation matrix, row-major.
    pub fn rotation_matrix(&self) -> [[f32; 3]; 3] {
        let [w, x, y, z] = self.rotation;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// The 4x4 homogeneous matrix, row-major.
    pub fn matrix(&self) -> [[f32; 4]; 4] {
        let r = self.rotation_matrix();
        let t = self.translation;
        [
            [r[0][0], r[0][1], r[0][2], t[0]],
            [r[1][0], r[1][1], r[1][2], t[1]],
            [r[2][0], r[2][1], r[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// Applies the transform to a point: `R p + t`.
    pub fn transform_point(&self, p: [f32; 3]) -> [f32; 3] {
        let r = self.rotation_matrix();
        let t = self.translation;
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + t[0],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + t[1],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + t[2],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalises_and_canonicalises() {
        let p = Pose::from_head_output(&[-2.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(p.rotation, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(p.transform_point([1.0, 1.0, 1.0]), [2.0, 3.0, 4.0]);
    }

    #[test]
    fn quarter_turn_about_z() {
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let p = Pose::from_head_output(&[h, 0.0, 0.0, h, 0.0, 0.0, 0.0]).unwrap();
        let q = p.transform_point([1.0, 0.0, 0.0]);
        assert!((q[0]).abs() < 1e-6 && (q[1] - 1.0).abs() < 1e-6 && q[2].abs() < 1e-6);
        let m = p.matrix();
        assert_eq!(m[3], [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn degenerate_outputs_are_errors() {
        assert_eq!(
            Pose::from_head_output(&[0.0; 7]),
            Err(Error::DegeneratePose)
        );
        assert_eq!(
            Pose::from_head_output(&[1.0, 0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0]),
            Err(Error::DegeneratePose)
        );
        assert_eq!(
            Pose::from_head_output(&[f32::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            Err(Error::DegeneratePose)
        );
    }
}
