//! Ambiguity: a surface of revolution reports its axis, a box reports the
//! half turn that fits as well, and an asymmetric shape reports neither.
//! Sources are the shapes' surfaces sampled afresh (no point shared with
//! the template), with noise, moved by a known pose.

mod common;
mod shapes;

use common::{angle_deg, rotation};
use pcrnet_core::ambiguity::{self, Ambiguity};
use pcrnet_core::format::Frame;
use pcrnet_core::pose::Pose;
use pcrnet_core::refine::{self, IcpSettings, Metric, Resolved, Subset};
use pcrnet_core::template::Template;
use pcrnet_core::testing::SplitMix64;
use shapes::template_of;

/// A point on the surface of the box `[-h, h]` (half sizes), faces chosen
/// by area.
fn on_box(rng: &mut SplitMix64, h: [f32; 3]) -> [f32; 3] {
    let areas = [h[1] * h[2], h[0] * h[2], h[0] * h[1]];
    let pick = rng.uniform(0.0, areas.iter().sum());
    let axis = if pick < areas[0] {
        0
    } else if pick < areas[0] + areas[1] {
        1
    } else {
        2
    };
    let mut p = [0f32; 3];
    for (k, v) in p.iter_mut().enumerate() {
        *v = rng.uniform(-h[k], h[k]);
    }
    p[axis] = if rng.uniform(0.0, 1.0) < 0.5 {
        -h[axis]
    } else {
        h[axis]
    };
    p
}

/// A point on a closed cylinder about z (radius `r`, half height `h`).
fn on_cylinder(rng: &mut SplitMix64, r: f32, h: f32) -> [f32; 3] {
    let side = 2.0 * h * r;
    let caps = r * r;
    let a = rng.uniform(0.0, std::f32::consts::TAU);
    if rng.uniform(0.0, side + caps) < side {
        [r * a.cos(), r * a.sin(), rng.uniform(-h, h)]
    } else {
        let s = r * rng.uniform(0.0, 1.0).sqrt();
        let z = if rng.uniform(0.0, 1.0) < 0.5 { -h } else { h };
        [s * a.cos(), s * a.sin(), z]
    }
}

/// A box with a post on one corner: no symmetry.
fn on_post_box(rng: &mut SplitMix64) -> [f32; 3] {
    if rng.uniform(0.0, 1.0) < 0.75 {
        on_box(rng, [0.45, 0.25, 0.1])
    } else {
        let p = on_box(rng, [0.06, 0.06, 0.2]);
        [p[0] + 0.35, p[1] + 0.15, p[2] + 0.3]
    }
}

fn sample(n: usize, seed: u64, noise: f32, f: fn(&mut SplitMix64) -> [f32; 3]) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| f(&mut rng).map(|v| v + rng.uniform(-noise, noise)))
        .collect()
}

const HALF_X: [f32; 4] = [0.0, 1.0, 0.0, 0.0];
const HALF_Y: [f32; 4] = [0.0, 0.0, 1.0, 0.0];
const HALF_Z: [f32; 4] = [0.0, 0.0, 0.0, 1.0];

const SETTINGS: IcpSettings = IcpSettings {
    metric: Metric::PointToPlane,
    iterations: 50,
    tolerance: 1e-4,
    max_distance: 0.3,
};

/// The template of `f`'s surface, a source sampled afresh and moved so
/// that `truth` maps it back, and what flip resolution from the truth
/// finds with every turn tried.
fn resolve_from_truth(
    f: fn(&mut SplitMix64) -> [f32; 3],
    truth: &Pose,
    seed: u64,
) -> (Template<'static>, Vec<[f32; 3]>, Resolved) {
    let template = template_of(&sample(900, seed, 0.0, f), &[HALF_X, HALF_Y, HALF_Z]);
    let back = truth.inverse();
    let source: Vec<[f32; 3]> = sample(400, seed + 100, 0.004, f)
        .into_iter()
        .map(|p| back.transform_point(p))
        .collect();
    let subset = Subset::new(&source, Frame::IDENTITY, 256);
    let r = refine::resolve(
        &template,
        &subset,
        *truth,
        4,
        10,
        &SETTINGS,
        0.05,
        &mut refine::Unguided,
    )
    .unwrap();
    (template, source, r)
}

fn assess(template: &Template<'_>, source: &[[f32; 3]], r: &Resolved) -> Ambiguity {
    let subset = Subset::new(source, Frame::IDENTITY, 256);
    ambiguity::assess(&Frame::IDENTITY, template, &subset, r, 0.05, 0.015)
}

fn truth() -> Pose {
    let mut t = rotation([0.3, -1.0, 0.5], 35.0);
    t.translation = [0.05, -0.1, 0.02];
    t
}

#[test]
fn a_cylinder_reports_its_axis_free() {
    let (template, source, r) = resolve_from_truth(|rng| on_cylinder(rng, 0.2, 0.4), &truth(), 1);
    let found = assess(&template, &source, &r);
    let axis = found.axis.expect("a cylinder's axis is free");
    assert!(axis.direction[2].abs() > 0.99, "{axis:?}");
    // The axis is the cylinder's: through the origin along z.
    let off = (axis.point[0].powi(2) + axis.point[1].powi(2)).sqrt();
    assert!(off < 0.02, "{axis:?}");
    assert!(axis.stiffness < ambiguity::FREE_AXIS_STIFFNESS);
}

#[test]
fn a_box_reports_the_half_turn_that_fits_as_well() {
    let (template, source, r) =
        resolve_from_truth(|rng| on_box(rng, [0.45, 0.25, 0.12]), &truth(), 2);
    let found = assess(&template, &source, &r);
    assert_eq!(found.axis, None, "a box has no free axis");
    let turn = found.turn.expect("a box's half turns fit as well");
    assert!(turn.degrees > 175.0, "{turn:?}");
    // The other pose is the chosen one turned: the motion composes to it
    // (up to f32 rounding: near 1 the dot product's ulp is 0.03 degrees of
    // `acos`, and composing rounds a few ulps).
    let rival = r.rival.unwrap();
    let apart = angle_deg(&r.pose.then(&turn.motion), &rival.pose);
    assert!(apart < 0.2, "{apart}");
    // The turn is one of the box's symmetries: about one of its axes.
    let [_, x, y, z] = turn.motion.rotation;
    let largest = x.abs().max(y.abs()).max(z.abs());
    assert!(largest > 0.99, "{turn:?}");
}

#[test]
fn an_asymmetric_shape_is_not_ambiguous() {
    for seed in 3..6 {
        let (template, source, r) = resolve_from_truth(on_post_box, &truth(), seed);
        assert!(angle_deg(&r.pose, &truth()) < 2.0, "{r:?}");
        let found = assess(&template, &source, &r);
        assert!(!found.is_ambiguous(), "seed {seed}: {found:?}");
        assert!(r.rival.is_some(), "the other finalist was refined");
    }
}

#[test]
fn the_sweep_finds_the_rival_of_a_box_turned_about_its_up_axis() {
    let f: fn(&mut SplitMix64) -> [f32; 3] = |rng| on_box(rng, [0.45, 0.25, 0.12]);
    let template = template_of(&sample(900, 7, 0.0, f), &[]);
    let truth = rotation([0.0, 0.0, 1.0], 20.0);
    let back = truth.inverse();
    let source: Vec<[f32; 3]> = sample(400, 8, 0.004, f)
        .into_iter()
        .map(|p| back.transform_point(p))
        .collect();
    let subset = Subset::new(&source, Frame::IDENTITY, 256);
    let starts = (0..12).map(|k| (k, rotation([0.0, 0.0, 1.0], 30.0 * k as f32)));
    let r = refine::resolve_starts(
        &template,
        &subset,
        starts,
        10,
        &SETTINGS,
        0.05,
        &mut refine::Unguided,
    )
    .unwrap();
    let found = assess(&template, &source, &r);
    let turn = found
        .turn
        .expect("the box turned half about z fits as well");
    assert!(turn.degrees > 175.0, "{turn:?}");
    assert!(turn.motion.rotation[3].abs() > 0.99, "about z: {turn:?}");
}
