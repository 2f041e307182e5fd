//! Seeded synthetic shapes and rigid transforms, for tests and demos that
//! must run without the ModelNet data.

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
        })
        .collect();
    normalise(&mut pts);
    pts
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

/// The similarity that centres a cloud on its centroid and scales it into
/// `[-0.5, 0.5]^3`: `p' = scale * (p - centre)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalisation {
    /// Centroid of the cloud it was computed on.
    pub centre: [f32; 3],
    /// Scale factor (1 for an empty or single-point cloud).
    pub scale: f32,
}

impl Normalisation {
    /// The normalisation of `pts` (identity for an empty cloud).
    pub fn of(pts: &[[f32; 3]]) -> Self {
        if pts.is_empty() {
            return Normalisation {
                centre: [0.0; 3],
                scale: 1.0,
            };
        }
        let n = pts.len() as f32;
        let mut c = [0f32; 3];
        for p in pts {
            for k in 0..3 {
                c[k] += p[k] / n;
            }
        }
        let extent = pts
            .iter()
            .flat_map(|p| (0..3).map(move |k| (p[k] - c[k]).abs()))
            .fold(0f32, f32::max);
        Normalisation {
            centre: c,
            scale: if extent > 0.0 { 0.5 / extent } else { 1.0 },
        }
    }

    /// Applies it in place.
    pub fn apply(&self, pts: &mut [[f32; 3]]) {
        for p in pts.iter_mut() {
            for (v, c) in p.iter_mut().zip(self.centre) {
                *v = (*v - c) * self.scale;
            }
        }
    }
}

/// Centres a cloud on its centroid and scales it so it fits in `[-0.5, 0.5]^3`.
pub fn normalise(pts: &mut [[f32; 3]]) {
    Normalisation::of(pts).apply(pts);
}

/// A random rigid transform with Euler angles in `+-max_deg` per axis and
/// translation in `+-max_t` per axis; returns the transformed cloud.
pub fn random_transform(pts: &[[f32; 3]], max_deg: f32, max_t: f32, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a: [f32; 3] = std::array::from_fn(|_| rng.random_range(-max_deg..=max_deg).to_radians());
    let t: [f32; 3] = std::array::from_fn(|_| rng.random_range(-max_t..=max_t));
    // R = Rz * Ry * Rx
    let r = crate::train::geometry::euler_to_mat(a);
    crate::train::geometry::transform_points(&r, &t, pts)
}
