//! Checking and refining poses against a template's points: ICP recovers
//! known transforms, flip resolution picks the right turn, the residual
//! tells good poses from bad ones, and the frame round-trips user units.

mod common;
mod shapes;

use common::{angle_deg, rotation};
use pcrnet_core::format::Frame;
use pcrnet_core::pose::Pose;
use pcrnet_core::refine::{self, Degeneracy, IcpSettings, Metric, Subset};
use pcrnet_core::template::Template;
use pcrnet_core::testing::SplitMix64;
use shapes::template_of;

/// An asymmetric "L" of 600 points in the model frame (about [-0.5, 0.5]).
fn ell(seed: u64) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    (0..600)
        .map(|i| {
            if i % 3 == 0 {
                [
                    rng.uniform(-0.5, -0.3),
                    rng.uniform(-0.5, 0.5),
                    rng.uniform(-0.1, 0.1),
                ]
            } else {
                [
                    rng.uniform(-0.5, 0.5),
                    rng.uniform(-0.5, -0.35),
                    rng.uniform(-0.1, 0.1),
                ]
            }
        })
        .collect()
}

#[test]
fn icp_recovers_a_known_transform() {
    let cloud = ell(1);
    let t = template_of(&cloud, &[]);
    // Source: the template moved by the inverse of `truth`, so `truth` maps it back.
    let mut truth = rotation([0.3, -1.0, 0.5], 12.0);
    truth.translation = [0.03, -0.02, 0.05];
    let inv = {
        let r = Pose {
            translation: [0.0; 3],
            ..truth
        };
        let conj = Pose {
            rotation: [
                r.rotation[0],
                -r.rotation[1],
                -r.rotation[2],
                -r.rotation[3],
            ],
            translation: [0.0; 3],
        };
        let t = conj.transform_point(truth.translation);
        Pose {
            translation: [-t[0], -t[1], -t[2]],
            ..conj
        }
    };
    let source: Vec<[f32; 3]> = cloud.iter().map(|&p| inv.transform_point(p)).collect();
    let subset = Subset::new(&source, Frame::IDENTITY, 256);
    for metric in [Metric::PointToPoint, Metric::PointToPlane] {
        let settings = IcpSettings {
            metric,
            iterations: 50,
            tolerance: 1e-6,
            max_distance: 0.2,
        };
        let (pose, iterations) = refine::icp(&t, &subset, Pose::IDENTITY, &settings);
        assert!(iterations > 1 && iterations <= 50, "{metric:?}");
        assert!(
            angle_deg(&pose, &truth) < 0.1,
            "{metric:?}: {pose:?} vs {truth:?}"
        );
        for k in 0..3 {
            assert!(
                (pose.translation[k] - truth.translation[k]).abs() < 1e-3,
                "{metric:?}: {pose:?}"
            );
        }
        let fit = refine::score(&t, &subset, &pose, 0.05);
        assert!(fit.residual < 1e-3 && fit.fitness == 1.0, "{fit:?}");
        // The identity is a worse fit.
        let off = refine::score(&t, &subset, &Pose::IDENTITY, 0.05);
        assert!(off.residual > 10.0 * fit.residual, "{off:?}");
    }
}

#[test]
fn flip_resolution_picks_the_turn_that_fits() {
    let cloud = ell(2);
    let half_z = [0.0, 0.0, 0.0, 1.0];
    let half_x = [0.0, 1.0, 0.0, 0.0];
    let t = template_of(&cloud, &[half_x, half_z]);
    // The source is the template turned half about z: the network's
    // "identity" is a flip; turn 2 (half about z) undoes it.
    let flip = Pose {
        rotation: half_z,
        translation: [0.0; 3],
    };
    let source: Vec<[f32; 3]> = cloud.iter().map(|&p| flip.transform_point(p)).collect();
    let subset = Subset::new(&source, Frame::IDENTITY, 300);
    let settings = IcpSettings {
        metric: Metric::PointToPoint,
        iterations: 10,
        tolerance: 1e-5,
        max_distance: 0.1,
    };
    let one = resolve_from_identity(&t, &subset, 1, 10, &settings, &mut refine::Unguided);
    let three = resolve_from_identity(&t, &subset, 3, 4, &settings, &mut refine::Unguided);
    assert_eq!(three.hypothesis, 2);
    assert!(three.fit.residual < 1e-3, "{three:?}");
    assert!(one.fit.residual > 10.0 * three.fit.residual, "{one:?}");
    assert!(angle_deg(&three.pose, &flip) < 0.1);

    // A test besides the residual (the view's, in `register_view`): one
    // that refuses the right fit leaves the lowest turned start it takes
    // to finish, so the right pose is not chosen; one that refuses every
    // fit changes nothing (the lowest finishes, as without a test).
    let mut refuse_flip = Accepting(|p: &Pose| angle_deg(p, &flip) > 10.0);
    let refusing = resolve_from_identity(&t, &subset, 3, 4, &settings, &mut refuse_flip);
    assert_ne!(refusing.hypothesis, 2, "{refusing:?}");
    assert!(angle_deg(&refusing.pose, &flip) > 10.0, "{refusing:?}");
    let mut refuse_all = Accepting(|_: &Pose| false);
    let none = resolve_from_identity(&t, &subset, 3, 4, &settings, &mut refuse_all);
    assert_eq!(none, three);

    // A guide that places every start: the network's own start put on the
    // right pose wins with one hypothesis, where unplaced it did not.
    let mut onto_flip = StartFrom(flip);
    let placed = resolve_from_identity(&t, &subset, 1, 10, &settings, &mut onto_flip);
    assert_eq!(placed.hypothesis, 0);
    assert!(angle_deg(&placed.pose, &flip) < 0.1, "{placed:?}");
    // An optional guide: none is no guide, some is the guide.
    let resolve =
        |guide: &mut Option<StartFrom>| resolve_from_identity(&t, &subset, 1, 10, &settings, guide);
    assert_eq!(resolve(&mut None), one);
    assert_eq!(resolve(&mut Some(StartFrom(flip))), placed);
}

/// Flip resolution of `subset` from the identity (the network's pose in
/// these tests), scoring within 0.05.
fn resolve_from_identity(
    t: &Template<'_>,
    subset: &Subset<'_>,
    hypotheses: usize,
    screen: usize,
    settings: &IcpSettings,
    guide: &mut impl refine::Guide,
) -> refine::Resolved {
    refine::resolve(
        t,
        subset,
        Pose::IDENTITY,
        hypotheses,
        screen,
        settings,
        0.05,
        guide,
    )
    .unwrap()
}

/// A guide with a test besides the residual, starts as given.
struct Accepting<F>(F);

impl<F: FnMut(&Pose) -> bool> refine::Guide for Accepting<F> {
    fn accept(&mut self, pose: &Pose) -> bool {
        (self.0)(pose)
    }

    fn may_refuse(&self) -> bool {
        true
    }
}

/// Screening drops a turned start that cannot win: from the right pose
/// the network's start fits, every turned start is far above it after
/// `SCREEN_CHECK` iterations and none is left to be the rival; with a
/// guide that may refuse starts (and here takes every one) all are screened
/// to the end and the best turned start is the rival. Where a turned start
/// wins (the source turned half about z), it is checked, kept and resumed:
/// the result is the one of screening it in one run, field for field.
#[test]
fn screening_drops_turned_starts_that_cannot_win() {
    let cloud = ell(4);
    let half_z = [0.0, 0.0, 0.0, 1.0];
    let half_x = [0.0, 1.0, 0.0, 0.0];
    let t = template_of(&cloud, &[half_x, half_z]);
    let settings = IcpSettings {
        metric: Metric::PointToPlane,
        iterations: 20,
        tolerance: 1e-5,
        max_distance: 0.3,
    };
    let flip = Pose {
        rotation: half_z,
        translation: [0.0; 3],
    };
    // Half about z and 8 degrees more: the winning turned start needs more
    // than `SCREEN_CHECK` iterations.
    let off_flip = flip.then(&rotation([0.3, 1.0, 0.2], 8.0));
    for (turn, winner) in [(Pose::IDENTITY, 0), (off_flip, 2)] {
        let mut rng = SplitMix64(9);
        let source: Vec<[f32; 3]> = cloud
            .iter()
            .map(|&p| {
                turn.transform_point(p)
                    .map(|v| v + rng.uniform(-0.01, 0.01))
            })
            .collect();
        let subset = Subset::new(&source, Frame::IDENTITY, 300);
        let screened = resolve_from_identity(
            &t,
            &subset,
            3,
            10,
            &settings,
            &mut Accepting(|_: &Pose| true),
        );
        let dropping = resolve_from_identity(&t, &subset, 3, 10, &settings, &mut refine::Unguided);
        assert_eq!(dropping.hypothesis, winner);
        // The pose takes the source back onto the template.
        assert!(
            angle_deg(&dropping.pose, &turn.inverse()) < 1.0,
            "{dropping:?}"
        );
        if winner == 0 {
            assert_eq!((dropping.pose, dropping.fit), (screened.pose, screened.fit));
            assert!(dropping.rival.is_none(), "{dropping:?}");
            let rival = screened.rival.expect("every turned start screened");
            assert!(rival.hypothesis > 0);
            assert!(
                rival.fit.residual > refine::SCREEN_DROP * dropping.fit.residual,
                "{rival:?}"
            );
        } else {
            // Checked after `SCREEN_CHECK` iterations, then resumed.
            assert!(
                dropping.icp_iterations > refine::SCREEN_CHECK,
                "{dropping:?}"
            );
            assert_eq!(dropping, screened);
        }
    }
    // An optional guide may refuse exactly when the guide may.
    type Test = fn(&Pose) -> bool;
    let none: Option<Accepting<Test>> = None;
    assert!(!refine::Guide::may_refuse(&none));
    assert!(refine::Guide::may_refuse(&Some(Accepting(|_: &Pose| true))));
    assert!(!refine::Guide::may_refuse(&refine::Unguided));
}

/// ICP resumed where a run stopped at its budget gives the pose one
/// longer run gives, bit for bit (what screening relies on when it
/// checks a start after `SCREEN_CHECK` iterations and goes on).
#[test]
fn icp_resumed_equals_one_run() {
    let cloud = ell(5);
    let t = template_of(&cloud, &[]);
    let turn = rotation([0.2, 1.0, -0.4], 20.0);
    let source: Vec<[f32; 3]> = cloud.iter().map(|&p| turn.transform_point(p)).collect();
    let subset = Subset::new(&source, Frame::IDENTITY, 256);
    for metric in [Metric::PointToPoint, Metric::PointToPlane] {
        let budget = |iterations| IcpSettings {
            metric,
            iterations,
            // Never met: every run ends at its budget.
            tolerance: 0.0,
            max_distance: 0.3,
        };
        let (whole, n) = refine::icp(&t, &subset, Pose::IDENTITY, &budget(10));
        let (part, a) = refine::icp(&t, &subset, Pose::IDENTITY, &budget(refine::SCREEN_CHECK));
        let (resumed, b) = refine::icp(&t, &subset, part, &budget(10 - refine::SCREEN_CHECK));
        assert_eq!((n, a + b), (10, 10), "{metric:?}");
        assert_eq!(resumed, whole, "{metric:?}");
    }
}

/// A guide that starts every screening from one pose.
struct StartFrom(Pose);

impl refine::Guide for StartFrom {
    fn place(&mut self, _start: Pose) -> Pose {
        self.0
    }
}

#[test]
fn degenerate_sources_are_flagged() {
    let cloud = ell(3);
    let t = template_of(&cloud, &[]);
    let point = vec![[0.1f32, 0.2, 0.3]; 40];
    let line: Vec<[f32; 3]> = (0..40).map(|i| [i as f32 * 0.01, 0.2, 0.3]).collect();
    // Far from the template's frame (beyond its int16 grid): still judged
    // by its own spread, not clamped onto the grid's edge.
    let far: Vec<[f32; 3]> = cloud.iter().map(|p| [p[0] + 1000.0, p[1], p[2]]).collect();
    let far_line: Vec<[f32; 3]> = line.iter().map(|p| [p[0] - 700.0, p[1], p[2]]).collect();
    for (cloud, expected) in [
        (&point, Some(Degeneracy::Point)),
        (&line, Some(Degeneracy::Line)),
        (&cloud, None),
        (&far, None),
        (&far_line, Some(Degeneracy::Line)),
    ] {
        let subset = Subset::new(cloud, Frame::IDENTITY, 256);
        assert_eq!(refine::degeneracy(&t, &subset, 1e-3), expected);
    }
}
