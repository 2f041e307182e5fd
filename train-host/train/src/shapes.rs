//! Seeded synthetic shapes and rigid transforms, for tests and demos that
//! must run without the ModelNet data.

use pcrnet_core::Frame;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Kinds of generated surfaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Surface of an axis-aligned box with side ratios 1 : 0.6 : 0.3.
    Box,
    /// Torus with radii 0.35 and 0.12.
    Torus,
    /// An "L" made of two boxes (no symmetry, good for registration).
    Ell,
    /// Closed cylinder about z, radius 0.25, height 1: free about its axis.
    Cylinder,
    /// Closed cone about z, base radius 0.4, height 1: free about its axis.
    Cone,
}

/// `n` points sampled on a shape, centred and scaled into the unit box.
pub fn sample(shape: Shape, n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pts: Vec<[f32; 3]> = (0..n)
        .map(|_| match shape {
            Shape::Box => box_surface(&mut rng, [1.0, 0.6, 0.3], [0.0; 3]),
            Shape::Torus => {
                let (u, v) = (
                    rng.random_range(0.0..std::f32::consts::TAU),
                    rng.random_range(0.0..std::f32::consts::TAU),
                );
                let r = 0.35 + 0.12 * v.cos();
                [r * u.cos(), r * u.sin(), 0.12 * v.sin()]
            }
            Shape::Ell => {
                if rng.random_bool(0.6) {
                    box_surface(&mut rng, [1.0, 0.25, 0.25], [0.0; 3])
                } else {
                    box_surface(&mut rng, [0.25, 0.7, 0.25], [-0.375, 0.475, 0.0])
                }
            }
            Shape::Cylinder => revolution_surface(&mut rng, 0.25, 0.25),
            Shape::Cone => revolution_surface(&mut rng, 0.4, 0.0),
        })
        .collect();
    normalise(&mut pts);
    pts
}

/// A point on the closed surface of revolution about z between the base
/// circle of radius `bottom` (z = -0.5) and the top circle of radius `top`
/// (z = 0.5; 0 for a cone's apex), side and caps chosen by area.
fn revolution_surface(rng: &mut ChaCha8Rng, bottom: f32, top: f32) -> [f32; 3] {
    let slant = ((bottom - top).powi(2) + 1.0).sqrt();
    let side = std::f32::consts::PI * (bottom + top) * slant;
    let (base, lid) = (
        std::f32::consts::PI * bottom * bottom,
        std::f32::consts::PI * top * top,
    );
    let a = rng.random_range(0.0..std::f32::consts::TAU);
    let pick = rng.random_range(0.0..side + base + lid);
    let (r, z) = if pick < side {
        // Uniform in area along the slant: the radius grows linearly.
        let u: f32 = rng.random_range(0.0..1.0);
        let (r0, r1) = (bottom, top);
        let t = if (r1 - r0).abs() < 1e-6 {
            u
        } else {
            ((r0 * r0 + u * (r1 * r1 - r0 * r0)).sqrt() - r0) / (r1 - r0)
        };
        (r0 + t * (r1 - r0), t - 0.5)
    } else if pick < side + base {
        (bottom * rng.random_range(0.0f32..1.0).sqrt(), -0.5)
    } else {
        (top * rng.random_range(0.0f32..1.0).sqrt(), 0.5)
    };
    [r * a.cos(), r * a.sin(), z]
}

fn box_surface(rng: &mut ChaCha8Rng, size: [f32; 3], centre: [f32; 3]) -> [f32; 3] {
    let areas = [size[1] * size[2], size[0] * size[2], size[0] * size[1]];
    let total: f32 = areas.iter().sum();
    let pick = rng.random_range(0.0..total);
    let axis = if pick < areas[0] {
        0
    } else if pick < areas[0] + areas[1] {
        1
    } else {
        2
    };
    let mut p = [0f32; 3];
    for (k, v) in p.iter_mut().enumerate() {
        *v = if k == axis {
            if rng.random_bool(0.5) {
                size[k] / 2.0
            } else {
                -size[k] / 2.0
            }
        } else {
            rng.random_range(-size[k] / 2.0..size[k] / 2.0)
        } + centre[k];
    }
    p
}

/// The frame that centres a cloud on its centroid and scales it into
/// `[-0.5, 0.5]^3`: `p_model = scale (p - centre)` ([`Frame::to_model`]).
/// The centroid is summed in f64 (as `pcrnet-core` does), so large or
/// repeated coordinates do not leave a residue. `None` for an empty cloud,
/// a non-finite coordinate or a cloud with no extent (all points equal).
pub fn frame_of(pts: &[[f32; 3]]) -> Option<Frame> {
    let centre = pcrnet_core::pose::centroid(pts).ok()?;
    let extent = pts
        .iter()
        .flat_map(|p| (0..3).map(move |k| (p[k] - centre[k]).abs()))
        .fold(0f32, f32::max);
    let scale = 0.5 / extent;
    (extent > 0.0 && scale.is_finite()).then_some(Frame { centre, scale })
}

/// The frame [`normalise`] applies: [`frame_of`], or for a cloud with no
/// extent only the centring.
pub fn normalising_frame(pts: &[[f32; 3]]) -> Frame {
    frame_of(pts).unwrap_or_else(|| Frame {
        centre: pcrnet_core::pose::centroid(pts).unwrap_or([0.0; 3]),
        scale: 1.0,
    })
}

/// Centres a cloud on its centroid and scales it so it fits in
/// `[-0.5, 0.5]^3` (see [`frame_of`]); a cloud with no extent is only centred.
pub fn normalise(pts: &mut [[f32; 3]]) {
    let frame = normalising_frame(pts);
    for p in pts.iter_mut() {
        *p = frame.to_model(*p);
    }
}

/// A random rigid transform with Euler angles in `+-max_deg` per axis and
/// translation in `+-max_t` per axis; returns the transformed cloud.
pub fn random_transform(pts: &[[f32; 3]], max_deg: f32, max_t: f32, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a: [f32; 3] = std::array::from_fn(|_| rng.random_range(-max_deg..=max_deg).to_radians());
    let t: [f32; 3] = std::array::from_fn(|_| rng.random_range(-max_t..=max_t));
    // R = Rz * Ry * Rx
    let r = crate::geometry::euler_to_mat(a);
    crate::geometry::transform_points(&r, &t, pts)
}
