//! Tracking steps on the shipped model: a smooth motion is kept frame
//! after frame without the network, a jump falls back to a registration
//! and recovers, and a previous pose that is not a pose is an error, one
//! that is far off never gives a wrong pose marked reliable.

mod common;

use common::{angle_deg, rotation, template};
use pcrnet_core::pose::{self, Pose};
use pcrnet_core::testing::SplitMix64;
use pcrnet_core::{Error, Int8Model, Options, TrackOutcome};

const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");

/// A rotation of `deg` degrees about `axis`, then `translation`.
fn posed(axis: [f32; 3], deg: f32, translation: [f32; 3]) -> Pose {
    Pose {
        translation,
        ..rotation(axis, deg)
    }
}

/// What a sensor sees when `truth` maps its points onto the template: a
/// seeded random 300 of the template's points moved by `truth^-1`, each
/// coordinate with Gaussian-like noise of about 0.3% of the template's
/// size (standard deviation).
fn frame(truth: &Pose, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    let back = truth.inverse();
    let t = template();
    (0..300)
        .map(|_| {
            let p = t[rng.int(0, t.len() as i32 - 1) as usize];
            let noise =
                [0; 3].map(|_: i32| (0..4).map(|_| rng.uniform(-0.003, 0.003)).sum::<f32>() * 0.87);
            let q = back.transform_point(p);
            [q[0] + noise[0], q[1] + noise[1], q[2] + noise[2]]
        })
        .collect()
}

fn model_and_scratch() -> (Int8Model<'static>, Vec<i8>) {
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let scratch = vec![0i8; model.scratch_len(1)];
    (model, scratch)
}

#[test]
fn a_smooth_motion_is_kept_without_the_network() {
    let (model, mut scratch) = model_and_scratch();
    let options = Options::default();
    // 60 frames at 30 frames a second: 60 deg/s about a tilted axis, and
    // a drift of a quarter of the template's size a second.
    let truth = |k: usize| {
        let k = k as f32;
        posed(
            [0.3, 1.0, 0.5],
            -20.0 + 2.0 * k,
            [0.008 * k, -0.004 * k, 0.002 * k],
        )
    };
    let first = model
        .register(&frame(&truth(0), 0), &options, &mut scratch)
        .unwrap();
    assert!(first.reliable && angle_deg(&first.pose, &truth(0)) < 0.5);
    let mut last = first.pose;
    for k in 1..60 {
        let t = model
            .track(&frame(&truth(k), k as u64), &last, &options, &mut scratch)
            .unwrap();
        let r = &t.registration;
        assert_eq!(t.outcome, TrackOutcome::Kept, "frame {k}: {t:?}");
        assert!(r.reliable && r.passes == 0 && r.hypothesis == 0, "{t:?}");
        let error = angle_deg(&r.pose, &truth(k));
        assert!(error < 0.5, "frame {k}: {error} deg");
        assert!(r.icp_iterations <= 6, "{t:?}");
        last = r.pose;
    }
}

#[test]
fn a_jump_falls_back_and_recovers() {
    let (model, mut scratch) = model_and_scratch();
    let options = Options::default();
    let before = posed([0.0, 0.0, 1.0], -40.0, [0.0; 3]);
    let after = posed([0.0, 0.0, 1.0], 50.0, [0.05, 0.0, 0.0]);
    let last = model
        .register(&frame(&before, 1), &options, &mut scratch)
        .unwrap();
    assert!(last.reliable);
    let t = model
        .track(&frame(&after, 2), &last.pose, &options, &mut scratch)
        .unwrap();
    assert_eq!(t.outcome, TrackOutcome::Recovered, "{t:?}");
    assert!(t.registration.reliable && t.registration.passes >= 1);
    let error = angle_deg(&t.registration.pose, &after);
    assert!(error < 1.0, "{error} deg");
}

#[test]
fn a_previous_pose_that_is_not_a_pose_is_an_error() {
    let (model, mut scratch) = model_and_scratch();
    let source = frame(&Pose::IDENTITY, 3);
    let options = Options::default();
    let nan = Pose {
        rotation: [f32::NAN, 0.0, 0.0, 0.0],
        ..Pose::IDENTITY
    };
    let scaled = Pose {
        rotation: [2.0, 0.0, 0.0, 0.0],
        ..Pose::IDENTITY
    };
    let far = Pose {
        translation: [f32::INFINITY, 0.0, 0.0],
        ..Pose::IDENTITY
    };
    for bad in [nan, scaled, far] {
        let e = model.track(&source, &bad, &options, &mut scratch);
        assert_eq!(e.unwrap_err(), Error::InvalidPose);
    }
    let mut with_nan = source.clone();
    with_nan[17][1] = f32::NAN;
    let e = model.track(&with_nan, &Pose::IDENTITY, &options, &mut scratch);
    assert_eq!(e.unwrap_err(), Error::NonFiniteCoordinate { index: 17 });
    assert_eq!(
        model.track(&[], &Pose::IDENTITY, &options, &mut scratch),
        Err(Error::EmptyCloud)
    );
}

/// Previous poses far off (a wrong turn, a translation of many template
/// sizes, a half turn): the step never keeps them, and whatever it
/// returns marked reliable is the right pose.
#[test]
fn a_far_off_previous_pose_is_never_kept_wrongly() {
    let (model, mut scratch) = model_and_scratch();
    let options = Options::default();
    let truth = posed([1.0, 0.2, 0.0], 25.0, [0.1, 0.0, -0.1]);
    let source = frame(&truth, 4);
    let wrong = [
        rotation([0.0, 1.0, 0.0], 180.0).then(&truth),
        rotation([1.0, 1.0, 1.0], 100.0).then(&truth),
        Pose {
            translation: [400.0, -250.0, 1e4],
            ..truth
        },
    ];
    for previous in wrong {
        let t = model
            .track(&source, &previous, &options, &mut scratch)
            .unwrap();
        assert_ne!(t.outcome, TrackOutcome::Kept, "{previous:?}: {t:?}");
        if t.registration.reliable {
            let error = angle_deg(&t.registration.pose, &truth);
            assert!(error < 1.0, "{previous:?}: reliable at {error} deg");
        }
    }
}

/// The constant-velocity prediction is exact for a constant motion.
#[test]
fn prediction_continues_a_constant_motion() {
    let step = posed([0.2, -0.5, 1.0], 7.0, [0.01, 0.02, -0.03]);
    let p0 = posed([1.0, 0.0, 0.3], 30.0, [0.3, -0.1, 0.2]);
    // Each frame's pose: the last one after one more step of the motion
    // (in the template's frame).
    let p1 = p0.then(&step);
    let p2 = p1.then(&step);
    let close = |a: &Pose, b: &Pose| {
        let q = a
            .rotation
            .iter()
            .zip(b.rotation)
            .all(|(x, y)| (x - y).abs() < 1e-5);
        let t = a
            .translation
            .iter()
            .zip(b.translation)
            .all(|(x, y)| (x - y).abs() < 1e-5);
        q && t
    };
    assert!(close(&pose::predict(&p0, &p1), &p2));
    // No motion predicts the last pose.
    assert!(close(&pose::predict(&p1, &p1), &p1));
    // A stream predicting from its own predictions keeps unit quaternions
    // (unnormalised, their norm error would triple each step).
    let (mut a, mut b) = (p0, p1);
    for _ in 0..1000 {
        (a, b) = (b, pose::predict(&a, &b));
    }
    let norm: f32 = b.rotation.iter().map(|v| v * v).sum();
    assert!((norm - 1.0).abs() < 1e-5, "{norm}");
    // The inverse undoes a pose.
    assert!(close(&p0.then(&p0.inverse()), &Pose::IDENTITY));
}
