//! One simulated sensor stream: an object moving along a smooth random
//! trajectory in front of a fixed depth camera ([`Trajectory`]), each
//! frame a fresh single view of it ([`frame`]), and the device pipeline
//! following it frame by frame ([`follow`]).
//!
//! Frames: the camera stays put; at time `t` the object's points `p`
//! (template frame) are at `M(t) p` in the sensor's frame. A frame is a
//! fresh random sampling of the shape's other points (none shared with the
//! template), moved by `M(t)`, cut to what the camera sees (the point
//! z-buffer of `pcrnet_train::view`, the camera along +z), then Gaussian
//! noise per coordinate. The true pose of the frame, the one a
//! registration should return, is `M(t)^-1` (`p_template = R p_source + t`).

use std::time::Instant;

use pcrnet_core::pose::{self, Pose};
use pcrnet_core::{Int8Model, Options, TrackOutcome};
use pcrnet_train::data::gaussian;
use pcrnet_train::geometry::{Mat3, apply, euler_to_mat, invert, quat_to_mat};
use pcrnet_train::metrics::{rotation_error_deg, translation_error};
use pcrnet_train::view::seen_from;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The fastest turn of a trajectory, degrees per second (the 90).
pub const MAX_TURN_RATE_DEG: f32 = 90.0;
/// The fastest shift of a trajectory, template sizes per second (half).
pub const MAX_SHIFT_RATE: f32 = 0.5;

/// A smooth random motion: each Euler angle and each coordinate a sine
/// about its start, `x(t) = x0 + a sin(w t)`, with `a w` a third of the
/// largest rate, so that the turn rate (at most the sum of the Euler
/// angles' rates) and the shift rate (at most the sum of the coordinates')
/// stay within [`MAX_TURN_RATE_DEG`] and [`MAX_SHIFT_RATE`]. The start
/// (`t = 0`) is a pose the network is trained for: Euler angles
/// U[-45, 45] degrees, translation U[-0.5, 0.5].
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    euler0: [f32; 3],
    turn: [(f32, f32); 3],
    shift0: [f32; 3],
    shift: [(f32, f32); 3],
}

impl Trajectory {
    /// The trajectory of `seed`: periods of 5 to 20 s per component.
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut sine = |peak_rate: f32| {
            let w = std::f32::consts::TAU / rng.random_range(5.0..20.0);
            (peak_rate / 3.0 / w, w)
        };
        let turn = [(); 3].map(|_| sine(MAX_TURN_RATE_DEG.to_radians()));
        let shift = [(); 3].map(|_| sine(MAX_SHIFT_RATE));
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5EED);
        Trajectory {
            euler0: [(); 3].map(|_| rng.random_range(-45f32..=45.0).to_radians()),
            turn,
            shift0: [(); 3].map(|_| rng.random_range(-0.5f32..=0.5)),
            shift,
        }
    }

    /// `M(t)`: template frame -> sensor frame, at `t` seconds.
    pub fn at(&self, t: f32) -> (Mat3, [f32; 3]) {
        let euler =
            std::array::from_fn(|k| self.euler0[k] + self.turn[k].0 * (self.turn[k].1 * t).sin());
        let shift =
            std::array::from_fn(|k| self.shift0[k] + self.shift[k].0 * (self.shift[k].1 * t).sin());
        (euler_to_mat(euler), shift)
    }

    /// The true pose of the frame at `t`: `M(t)^-1`.
    pub fn truth(&self, t: f32) -> (Mat3, [f32; 3]) {
        let (r, s) = self.at(t);
        invert(&r, &s)
    }
}

/// The frame at `t` of an object whose other points are `rest` (template
/// frame): `points` of them (all, if fewer) drawn without replacement
/// with `seed`, moved by `M(t)`, cut to the view from +z, with noise
/// `sigma` per coordinate; and where the view's camera stood
/// (`pcrnet_train::view::eye`, `None` for fewer than two points).
pub fn frame(
    rest: &[[f32; 3]],
    points: usize,
    trajectory: &Trajectory,
    t: f32,
    sigma: f32,
    seed: u64,
) -> (Vec<[f32; 3]>, Option<[f32; 3]>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (r, s) = trajectory.at(t);
    let drawn = rand::seq::index::sample(&mut rng, rest.len(), points.min(rest.len()));
    let moved: Vec<[f32; 3]> = drawn.iter().map(|i| apply(&r, &s, &rest[i])).collect();
    let (visible, eye) = seen_from(&moved, UP);
    let seen = visible
        .into_iter()
        .map(|i| moved[i].map(|v| v + sigma * gaussian(&mut rng)))
        .collect();
    (seen, eye)
}

/// The direction the frames are seen from.
const UP: [f32; 3] = [0.0, 0.0, 1.0];

/// What happened to one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Step {
    /// Registered afresh (the first frame, or after a frame without a
    /// reliable pose), and reliable.
    Registered,
    /// Tracked from the last pose, kept.
    Kept,
    /// Tracked, fell back to the registration, which was reliable.
    Recovered,
    /// No reliable pose: a tracking step that found none either way, or a
    /// fresh registration that was not reliable.
    Lost,
}

/// One frame's result.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameResult {
    /// Seconds since the sequence began.
    pub t: f32,
    /// What the step did.
    pub step: Step,
    /// Rotation error, degrees.
    pub rotation_deg: f64,
    /// Translation error, template sizes.
    pub translation: f64,
    /// Whether the pose was marked reliable.
    pub reliable: bool,
    /// The pose's relative plane residual (what the verdict judges).
    pub residual: f32,
    /// Whether the result reported the pose ambiguous (a free axis or a
    /// turn that fits about as well).
    pub ambiguous: bool,
    /// Points the camera saw.
    pub points: usize,
    /// Host time of the call, microseconds (one thread).
    pub micros: f64,
    /// Whether the pose explains the frame's view from its camera
    /// (`Int8Model::check_view`, checked after the step: the step itself
    /// does not use it); `None` when it could not be checked.
    #[serde(default)]
    pub view_passed: Option<bool>,
}

/// Follows a sequence of `frames` frames at `rate` frames a second with
/// `model` (the template bound in) and `options`: frames registered afresh
/// until one is reliable (`register_view` from the frame's camera: the
/// sensor's position is known; `register` for a frame without one); then
/// every frame a tracking step (`track_view`, else `track`) from the constant-velocity
/// prediction of the last two poses (the last pose alone after a
/// registration or a lost frame). After a lost frame the next is tracked
/// from the last reliable pose: the step's ICP from there, then its
/// registration, so the fresh registration is still tried.
#[allow(clippy::too_many_arguments, reason = "the simulation's knobs")]
pub fn follow(
    model: &Int8Model<'_>,
    rest: &[[f32; 3]],
    points: usize,
    trajectory: &Trajectory,
    frames: usize,
    rate: f32,
    sigma: f32,
    options: &Options,
    seed: u64,
) -> Result<Vec<FrameResult>, pcrnet_core::Error> {
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let mut view = vec![0f32; pcrnet_core::scene::view::buffer_len(crate::register::VIEW_SIDE)];
    let (mut last, mut before): (Option<Pose>, Option<Pose>) = (None, None);
    let mut out = Vec::with_capacity(frames);
    for k in 0..frames {
        let t = k as f32 / rate;
        let (source, camera) = frame(
            rest,
            points,
            trajectory,
            t,
            sigma,
            seed.wrapping_add(k as u64),
        );
        let started = Instant::now();
        let (r, step) = match last {
            None => {
                let r = match camera {
                    Some(at) => {
                        model
                            .register_view(&source, at, options, &mut scratch, &mut view)?
                            .registration
                    }
                    None => model.register(&source, options, &mut scratch)?,
                };
                let step = if r.reliable {
                    Step::Registered
                } else {
                    Step::Lost
                };
                (r, step)
            }
            Some(last) => {
                let start = before.map_or(last, |b| pose::predict(&b, &last));
                let tracked = match camera {
                    Some(at) => {
                        model.track_view(&source, &start, at, options, &mut scratch, &mut view)?
                    }
                    None => model.track(&source, &start, options, &mut scratch)?,
                };
                let step = match tracked.outcome {
                    TrackOutcome::Kept => Step::Kept,
                    TrackOutcome::Recovered => Step::Recovered,
                    TrackOutcome::Lost => Step::Lost,
                };
                (tracked.registration, step)
            }
        };
        let micros = started.elapsed().as_secs_f64() * 1e6;
        (before, last) = match (step, last) {
            // Coast: the next frame is tracked from the last reliable pose
            // (a step falls back to the registration anyway), no velocity.
            (Step::Lost, last) => (None, last),
            // A fresh pose: no velocity across it.
            (Step::Registered | Step::Recovered, _) | (Step::Kept, None) => (None, Some(r.pose)),
            (Step::Kept, Some(previous)) => (Some(previous), Some(r.pose)),
        };
        let view_passed = camera.and_then(|at| {
            let checked = model.check_view(&source, at, &r.pose, &mut view);
            checked.ok().map(|v| v.passed)
        });
        let (r_gt, t_gt) = trajectory.truth(t);
        out.push(FrameResult {
            t,
            step,
            rotation_deg: rotation_error_deg(&quat_to_mat(r.pose.rotation), &r_gt),
            translation: translation_error(&r.pose.translation, &t_gt),
            reliable: r.reliable,
            residual: r.relative_plane_residual,
            ambiguous: r.ambiguity.is_ambiguous(),
            points: source.len(),
            micros,
            view_passed,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trajectories_keep_to_their_rates_and_start_in_range() {
        for seed in 0..20 {
            let tr = Trajectory::new(seed);
            let dt = 0.01f32;
            let mut fastest: (f64, f64) = (0.0, 0.0);
            for k in 0..1000 {
                let (a, b) = (tr.at(k as f32 * dt), tr.at((k + 1) as f32 * dt));
                let turn = rotation_error_deg(&a.0, &b.0) / dt as f64;
                let shift = translation_error(&a.1, &b.1) / dt as f64;
                fastest = (fastest.0.max(turn), fastest.1.max(shift));
            }
            assert!(fastest.0 <= MAX_TURN_RATE_DEG as f64 * 1.01, "{fastest:?}");
            assert!(fastest.1 <= MAX_SHIFT_RATE as f64 * 1.01, "{fastest:?}");
            // It does move: at least a fifth of the limits somewhere.
            assert!(fastest.0 > 18.0 && fastest.1 > 0.1, "{fastest:?}");
            assert_eq!(tr, Trajectory::new(seed));
        }
    }

    #[test]
    fn a_frame_is_a_view_of_the_moved_shape() {
        let shapes = pcrnet_train::dataset::Dataset::generated(1, 512, 3);
        let tr = Trajectory::new(4);
        let (f, camera) = frame(&shapes.rest[0], 512, &tr, 1.5, 0.0, 9);
        // One side: fewer points than drawn, but a good share of them.
        assert!(f.len() < 480 && f.len() > 80, "{}", f.len());
        // Moved back by the truth, every point lies on the shape.
        let (r, t) = tr.truth(1.5);
        for p in &f {
            let q = apply(&r, &t, p);
            let near = shapes.rest[0]
                .iter()
                .map(|s| (0..3).map(|k| (s[k] - q[k]).powi(2)).sum::<f32>())
                .fold(f32::MAX, f32::min);
            assert!(near < 1e-8, "{near}");
        }
        assert_eq!(
            (f.clone(), camera),
            frame(&shapes.rest[0], 512, &tr, 1.5, 0.0, 9)
        );
        // The camera looks down at the frame from above (+z).
        let camera = camera.unwrap();
        assert!(f.iter().all(|p| p[2] < camera[2]));
    }
}
