//! Helpers the pose tests share: a rotation about an axis, the angle
//! between two rotations, and the shipped model's template.

use pcrnet_core::pose::Pose;

/// A rotation of `deg` degrees about `axis` (any length), no translation.
pub fn rotation(axis: [f32; 3], deg: f32) -> Pose {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let h = deg.to_radians() / 2.0;
    Pose {
        rotation: [
            h.cos(),
            h.sin() * axis[0] / n,
            h.sin() * axis[1] / n,
            h.sin() * axis[2] / n,
        ],
        translation: [0.0; 3],
    }
}

/// The angle between the rotations of `a` and `b`, degrees.
pub fn angle_deg(a: &Pose, b: &Pose) -> f32 {
    let d: f32 = a.rotation.iter().zip(b.rotation).map(|(x, y)| x * y).sum();
    2.0 * d.abs().min(1.0).acos().to_degrees()
}

/// The shipped model's template (`models/embedded-default-template.xyz`,
/// user units). Not every test that shares these helpers reads it.
#[allow(dead_code)]
pub fn template() -> Vec<[f32; 3]> {
    include_str!("../../../models/embedded-default-template.xyz")
        .lines()
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}
