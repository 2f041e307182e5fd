//! Evaluation: the baselines the networks are compared with (ICP, PointNetLK).

pub mod icp;
pub mod plot;
pub mod methods;
pub mod metrics;
pub mod pairs;
pub mod pointnetlk;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use pcrnet_core::Pose;

/// A [`Pose`] from an f64 rotation matrix and translation (quaternion with
/// `w >= 0`, as `pcrnet-core` makes them).
pub fn pose_from_matrix(r: &Matrix3<f64>, t: &Vector3<f64>) -> Pose {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    Pose {
        rotation: [
            (s * q.w) as f32,
            (s * q.i) as f32,
            (s * q.j) as f32,
            (s * q.k) as f32,
        ],
        translation: [t.x as f32, t.y as f32, t.z as f32],
    }
}
