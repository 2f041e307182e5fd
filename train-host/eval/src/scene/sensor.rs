//! What real depth sensors do at depth edges, added to a rendered frame.
//!
//! The renderer ([`pcrnet_core::testing::scene`]) gives every pixel the
//! depth of the first surface its ray meets, plus noise. Real sensors fail
//! where a pixel straddles two surfaces at different depths:
//!
//! - **time-of-flight** cameras mix the light returned by both: *flying
//!   pixels* with a depth between the near and the far surface, floating
//!   in free space beside every silhouette (and a few edge pixels the
//!   camera's own filter invalidates);
//! - **structured-light** RGB-D cameras (a Kinect's) cannot match their
//!   pattern there: *missing pixels* along silhouettes, more on the side
//!   the projector cannot see (its *shadow*: the background beside an
//!   object's edge, on the side away from the projector, which sits beside
//!   the camera along x).
//!
//! A pixel is at an edge when one of its four neighbours differs in depth
//! by more than [`EDGE_JUMP`] plus [`EDGE_SHARE`] of its depth. Each camera
//! applies its own model ([`Artifacts`]) with seeded draws; pixels are
//! judged on the frame as rendered, so the result does not depend on the
//! order they are visited in.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A depth step (metres) beyond which neighbouring pixels see different
/// surfaces...
pub const EDGE_JUMP: f32 = 0.02;
/// ...plus this share of the pixel's depth.
pub const EDGE_SHARE: f32 = 0.02;

/// How a camera fails at depth edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Artifacts {
    /// None: the frame as rendered.
    None,
    /// Time-of-flight.
    TimeOfFlight {
        /// Probability that an edge pixel becomes a flying pixel: its depth
        /// drawn uniformly between its own and its most different
        /// neighbour's.
        flying: f32,
        /// Probability that an edge pixel is invalidated instead (one draw:
        /// below `flying` it flies, below `flying + dropped` it is dropped).
        dropped: f32,
    },
    /// Structured light.
    StructuredLight {
        /// Probability that an edge pixel is invalidated.
        dropped: f32,
        /// Pixels invalidated beside a near surface's edge on the far side
        /// (towards +x, away from the projector): its shadow, of a fixed
        /// width whatever the depth step (a simplification: a real
        /// shadow widens with the step and narrows with distance).
        shadow: usize,
    },
}

impl Artifacts {
    /// A short description for reports.
    pub fn describe(&self) -> String {
        match *self {
            Artifacts::None => "none".into(),
            Artifacts::TimeOfFlight { flying, dropped } => format!(
                "flying pixels at depth edges ({:.0}% of edge pixels; {:.0}% invalid)",
                100.0 * flying,
                100.0 * dropped
            ),
            Artifacts::StructuredLight { dropped, shadow } => format!(
                "missing pixels at depth edges ({:.0}% of edge pixels) and a {shadow}-pixel projector shadow beside near edges",
                100.0 * dropped
            ),
        }
    }
}

/// Applies `artifacts` to `depth` (`width x height` raw values, `scale`
/// metres each, 0 invalid), drawing from `seed`.
pub fn apply(
    depth: &mut [u16],
    width: usize,
    height: usize,
    scale: f32,
    artifacts: Artifacts,
    seed: u64,
) {
    if artifacts == Artifacts::None {
        return;
    }
    let rendered = depth.to_vec();
    let metres = |i: usize| f32::from(rendered[i]) * scale;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for v in 0..height {
        for u in 0..width {
            let i = v * width + u;
            if rendered[i] == 0 {
                continue;
            }
            let z = metres(i);
            // The neighbour whose depth differs most.
            let neighbours = [
                (u > 0).then(|| i - 1),
                (u + 1 < width).then(|| i + 1),
                (v > 0).then(|| i - width),
                (v + 1 < height).then(|| i + width),
            ];
            let Some((far, step)) = neighbours
                .into_iter()
                .flatten()
                .filter(|&n| rendered[n] != 0)
                .map(|n| (n, metres(n) - z))
                .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            else {
                continue;
            };
            let edge = EDGE_JUMP + EDGE_SHARE * z;
            if step.abs() <= edge {
                continue;
            }
            match artifacts {
                Artifacts::None => {}
                Artifacts::TimeOfFlight { flying, dropped } => {
                    let draw: f32 = rng.random();
                    if draw < flying {
                        let mixed = z + rng.random::<f32>() * (metres(far) - z);
                        depth[i] = (mixed / scale).round() as u16;
                    } else if draw < flying + dropped {
                        depth[i] = 0;
                    }
                }
                Artifacts::StructuredLight { dropped, shadow } => {
                    if rng.random::<f32>() < dropped {
                        depth[i] = 0;
                    }
                    // The near side of an edge whose far side lies to its
                    // right: the projector cannot light the next pixels.
                    let right = u + 1 < width && rendered[i + 1] != 0;
                    if right && metres(i + 1) - z > edge {
                        for k in 1..=shadow {
                            if u + k < width {
                                depth[i + k] = 0;
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A near square (1 m) on a far wall (2 m), 20 x 20 pixels.
    fn frame() -> Vec<u16> {
        let mut depth = vec![2000u16; 400];
        for v in 5..15 {
            for u in 5..15 {
                depth[v * 20 + u] = 1000;
            }
        }
        depth
    }

    #[test]
    fn only_edges_change_and_the_draws_are_seeded() {
        let flat = vec![1500u16; 400];
        for artifacts in [
            Artifacts::TimeOfFlight {
                flying: 0.6,
                dropped: 0.1,
            },
            Artifacts::StructuredLight {
                dropped: 0.7,
                shadow: 2,
            },
        ] {
            let mut d = flat.clone();
            apply(&mut d, 20, 20, 0.001, artifacts, 1);
            assert_eq!(d, flat, "{artifacts:?} changed a frame without edges");
            let (mut a, mut b) = (frame(), frame());
            apply(&mut a, 20, 20, 0.001, artifacts, 7);
            apply(&mut b, 20, 20, 0.001, artifacts, 7);
            assert_eq!(a, b);
            let original = frame();
            for v in 0..20 {
                for u in 0..20 {
                    let i = v * 20 + u;
                    // Two pixels or more inside or outside the square's
                    // border: untouched (the shadow reaches two to the right).
                    let inside = (7..13).contains(&u) && (7..13).contains(&v);
                    let outside = !(3..18).contains(&u) || !(3..17).contains(&v);
                    if inside || outside {
                        assert_eq!(a[i], original[i], "{artifacts:?} at ({u}, {v})");
                    }
                }
            }
            assert_ne!(a, original, "{artifacts:?} changed nothing");
        }
    }

    #[test]
    fn flying_pixels_lie_between_the_surfaces_and_shadows_right_of_near_edges() {
        let mut d = frame();
        let flying = Artifacts::TimeOfFlight {
            flying: 1.0,
            dropped: 0.0,
        };
        apply(&mut d, 20, 20, 0.001, flying, 3);
        let between = d.iter().filter(|&&z| z > 1000 && z < 2000).count();
        assert!(between > 30, "{between} flying pixels");
        assert!(d.iter().all(|&z| (1000..=2000).contains(&z)));
        let mut d = frame();
        let shadowed = Artifacts::StructuredLight {
            dropped: 0.0,
            shadow: 2,
        };
        apply(&mut d, 20, 20, 0.001, shadowed, 3);
        for v in 0..20 {
            let missing: Vec<usize> = (0..20).filter(|&u| d[v * 20 + u] == 0).collect();
            let want: Vec<usize> = if (5..15).contains(&v) {
                vec![15, 16]
            } else {
                vec![]
            };
            assert_eq!(missing, want, "row {v}");
        }
    }
}
