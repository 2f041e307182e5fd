//! A cut single view checked from its viewpoint (`scene::view`): a box seen
//! from one side passes at its true pose, and fails when turned, shifted,
//! or when the view is a fragment of it; bad viewpoints and buffers are
//! typed errors.

mod shapes;

use pcrnet_core::format::Frame;
use pcrnet_core::scene::view::{self, View};
use pcrnet_core::scene::visible;
use pcrnet_core::scene::{Verification, VerifySettings};
use pcrnet_core::{Error, Pose};

/// Half sizes of the box (user units = model units here).
const HALF: [f32; 3] = [0.3, 0.2, 0.125];

/// The box's surface on a grid of `spacing`, shifted by `offset` (a
/// fraction of the spacing) so that two samplings share no point; with
/// each point's outward face normal.
fn box_surface(spacing: f32, offset: f32) -> Vec<([f32; 3], [f32; 3])> {
    let mut out = Vec::new();
    for axis in 0..3 {
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        for sign in [-1.0f32, 1.0] {
            let steps = |k: usize| (2.0 * HALF[k] / spacing) as i32;
            for i in 0..steps(a) {
                for j in 0..steps(b) {
                    let mut p = [0f32; 3];
                    p[axis] = sign * HALF[axis];
                    p[a] = -HALF[a] + (i as f32 + offset) * spacing;
                    p[b] = -HALF[b] + (j as f32 + offset) * spacing;
                    let mut n = [0f32; 3];
                    n[axis] = sign;
                    out.push((p, n));
                }
            }
        }
    }
    out
}

const EYE: [f32; 3] = [0.5, -0.7, 1.4];

/// What a sensor at `EYE` sees of the box (a convex shape: the faces
/// turned towards it).
fn seen(spacing: f32, keep: impl Fn([f32; 3]) -> bool) -> Vec<[f32; 3]> {
    box_surface(spacing, 0.5)
        .into_iter()
        .filter(|(p, n)| (0..3).map(|k| n[k] * (EYE[k] - p[k])).sum::<f32>() > 0.0)
        .map(|(p, _)| p)
        .filter(|&p| keep(p))
        .collect()
}

fn template() -> pcrnet_core::template::Template<'static> {
    let cloud: Vec<[f32; 3]> = box_surface(0.05, 0.0).into_iter().map(|(p, _)| p).collect();
    shapes::template_of(&cloud, &[])
}

fn settings(t: &pcrnet_core::template::Template<'_>) -> VerifySettings {
    VerifySettings::for_object(t.radius())
}

fn check(source: &[[f32; 3]], viewpoint: [f32; 3], pose: &Pose) -> Verification {
    let t = template();
    let mut buffer = vec![0f32; view::buffer_len(32)];
    let v = View::render(source, viewpoint, &mut buffer).unwrap();
    v.check(&t, &Frame::IDENTITY, pose, &settings(&t))
}

/// A turn of `deg` degrees about the unit axis `axis`.
fn turn(axis: [f32; 3], deg: f32) -> Pose {
    let h = deg.to_radians() / 2.0;
    Pose {
        rotation: [
            h.cos(),
            axis[0] * h.sin(),
            axis[1] * h.sin(),
            axis[2] * h.sin(),
        ],
        translation: [0.0; 3],
    }
}

#[test]
fn the_true_pose_explains_the_view() {
    let source = seen(0.03, |_| true);
    let v = check(&source, EYE, &Pose::IDENTITY);
    assert!(v.passed, "{v:?}");
    assert!(
        v.supported > 100 && v.violations <= v.supported / 20,
        "{v:?}"
    );
    // The far faces are behind the seen ones.
    assert!(v.occluded > 50, "{v:?}");
}

#[test]
fn the_true_pose_passes_in_any_frame() {
    // The source and its viewpoint moved together: the pose maps them back.
    let moved = Pose {
        translation: [0.4, -1.0, 2.5],
        ..turn([0.48, 0.6, 0.64], 70.0)
    };
    let source: Vec<[f32; 3]> = seen(0.03, |_| true)
        .iter()
        .map(|&p| moved.transform_point(p))
        .collect();
    let v = check(&source, moved.transform_point(EYE), &moved.inverse());
    assert!(v.passed, "{v:?}");
}

#[test]
fn a_turned_or_shifted_pose_leaves_template_points_in_free_space() {
    let source = seen(0.03, |_| true);
    let quarter = check(&source, EYE, &turn([0.0, 0.0, 1.0], 90.0));
    assert!(!quarter.passed, "{quarter:?}");
    let shifted = Pose {
        translation: [0.15, 0.0, 0.0],
        ..Pose::IDENTITY
    };
    let shifted = check(&source, EYE, &shifted);
    assert!(!shifted.passed, "{shifted:?}");
    assert!(shifted.violations > shifted.supported / 5, "{shifted:?}");
}

#[test]
fn a_fragment_cannot_pass_for_the_object() {
    // A quarter of the box, cut along x and y: fitted where it belongs, the
    // rest of the box's near side lies where the sensor saw nothing.
    let fragment = seen(0.015, |p| p[0] > 0.0 && p[1] < 0.0);
    let v = check(&fragment, EYE, &Pose::IDENTITY);
    assert!(!v.passed, "{v:?}");
    assert!(v.violations > v.supported, "{v:?}");
}

#[test]
fn bad_viewpoints_buffers_and_clouds_are_typed_errors() {
    let source = seen(0.03, |_| true);
    let mut buffer = vec![0f32; view::buffer_len(32)];
    let invalid = |r: Result<View<'_>, Error>| matches!(r, Err(Error::InvalidOption { .. }));
    assert!(invalid(View::render(
        &source,
        [f32::NAN, 0.0, 1.0],
        &mut buffer
    )));
    // Inside the box: points on every side.
    assert!(invalid(View::render(
        &source,
        [0.01, 0.02, 0.03],
        &mut buffer
    )));
    assert!(invalid(View::render(&source, EYE, &mut [0f32; 63])));
    assert!(matches!(
        View::render(&[], EYE, &mut buffer),
        Err(Error::EmptyCloud)
    ));
    assert!(matches!(
        View::render(&[[f32::INFINITY; 3]], EYE, &mut buffer),
        Err(Error::EmptyCloud)
    ));
    // A smaller buffer renders coarser pixels, still a check.
    let mut small = vec![0f32; view::buffer_len(view::MIN_SIDE)];
    let v = View::render(&source, EYE, &mut small).unwrap();
    assert_eq!(v.side(), view::MIN_SIDE);
}

const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");

/// The shipped template's near side from +z (a z-buffer of its stored
/// points on an 8 x 8 grid) moved by a small motion, with the viewpoint
/// moved alike, and the true pose (the motion undone).
fn shipped_view(model: &pcrnet_core::Int8Model<'_>) -> (Vec<[f32; 3]>, [f32; 3], Pose) {
    let t = model.template();
    let cloud: Vec<[f32; 3]> = (0..t.len())
        .map(|i| t.user_point(i, model.frame()))
        .collect();
    let n = cloud.len() as f32;
    let c: [f32; 3] = std::array::from_fn(|k| cloud.iter().map(|p| p[k]).sum::<f32>() / n);
    let radius = model.object_radius();
    let cell = 2.0 * radius / 8.0;
    let at = |p: &[f32; 3]| {
        let i = |k: usize| (((p[k] - c[k] + radius) / cell).max(0.0) as usize).min(7);
        i(1) * 8 + i(0)
    };
    let mut top = [f32::MIN; 64];
    for p in &cloud {
        top[at(p)] = top[at(p)].max(p[2]);
    }
    let motion = Pose {
        translation: [0.1, -0.05, 0.2],
        ..turn([0.6, 0.0, 0.8], 25.0)
    };
    let seen = cloud
        .iter()
        .filter(|p| p[2] >= top[at(p)] - cell)
        .map(|&p| motion.transform_point(p))
        .collect();
    (
        seen,
        motion.transform_point([c[0], c[1], c[2] + 3.0 * radius]),
        motion.inverse(),
    )
}

/// How far apart two poses are: the angle between their rotations
/// (degrees) and the distance between their translations.
fn apart(a: &Pose, b: &Pose) -> (f32, f32) {
    let d: f32 = a.rotation.iter().zip(b.rotation).map(|(x, y)| x * y).sum();
    let t: f32 = (0..3)
        .map(|k| (a.translation[k] - b.translation[k]).powi(2))
        .sum();
    (2.0 * d.abs().min(1.0).acos().to_degrees(), t.sqrt())
}

#[test]
fn a_viewed_registration_finds_the_pose_and_carries_its_check() {
    let model = pcrnet_core::Int8Model::from_bytes(MODEL).unwrap();
    let (source, at, truth) = shipped_view(&model);
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let mut buffer = vec![0f32; view::buffer_len(32)];
    let options = pcrnet_core::Options::default();
    let viewed = model
        .register_view(&source, at, &options, &mut scratch, &mut buffer)
        .unwrap();
    let plain = model.register(&source, &options, &mut scratch).unwrap();
    // Both find the pose; the view's starts are placed by what the sensor
    // sees, so the registration is not the same bit for bit.
    let radius = model.object_radius();
    for (r, what) in [(&viewed.registration, "viewed"), (&plain, "plain")] {
        let (angle, shift) = apart(&r.pose, &truth);
        assert!(
            angle < 1.0 && shift < 0.02 * radius,
            "{what}: {angle} deg, {shift}"
        );
    }
    assert!(viewed.reliable && viewed.view.passed, "{viewed:?}");
    let again = model
        .check_view(&source, at, &viewed.registration.pose, &mut buffer)
        .unwrap();
    assert_eq!(again, viewed.view);

    // Bad input: the source's errors first, then the view's.
    let mut broken = source.clone();
    broken[3][1] = f32::NAN;
    assert!(matches!(
        model.register_view(&broken, at, &options, &mut scratch, &mut buffer),
        Err(Error::NonFiniteCoordinate { index: 3 })
    ));
    assert!(matches!(
        model.register_view(&source, source[0], &options, &mut scratch, &mut buffer),
        Err(Error::InvalidOption { .. })
    ));
    let nan = Pose {
        translation: [f32::NAN; 3],
        ..truth
    };
    let stretched = Pose {
        rotation: [2.0, 0.0, 0.0, 0.0],
        ..truth
    };
    for bad in [nan, stretched] {
        assert!(matches!(
            model.check_view(&source, at, &bad, &mut buffer),
            Err(Error::InvalidPose)
        ));
    }
    // Another frame's coordinates: 100,000 radii away.
    let far = [at[0] + 1e5 * model.object_radius(), at[1], at[2]];
    assert!(matches!(
        model.check_view(&source, far, &viewed.registration.pose, &mut buffer),
        Err(Error::InvalidOption { .. })
    ));
}

#[test]
fn a_start_is_placed_by_what_the_sensor_sees() {
    let model = pcrnet_core::Int8Model::from_bytes(MODEL).unwrap();
    let (source, at, truth) = shipped_view(&model);
    let (frame, template) = (model.frame(), model.template());
    let to_model = |p: [f32; 3]| frame.to_model(p);
    let n = source.len() as f32;
    let centroid: [f32; 3] =
        std::array::from_fn(|k| source.iter().map(|p| to_model(*p)[k]).sum::<f32>() / n);
    let truth = frame.pose_to_model(&truth);
    // The sensor above the template sees its top: the visible points'
    // centroid lies above the template's centre, where the view's
    // centroid lands at the true pose.
    let eye = truth.transform_point(to_model(at));
    let seen = visible::visible_centroid(template, eye, [0.0; 3]).unwrap();
    let landed = truth.transform_point(centroid);
    let gap = |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
    assert!(seen[2] > 0.02, "{seen:?} {landed:?}");
    assert!(gap(seen, landed) < 0.05, "{seen:?} {landed:?}");
    // A start with the true rotation that puts the view's centroid on the
    // template's centre (as the network's centring does) is placed near
    // the truth.
    let centred = Pose {
        translation: std::array::from_fn(|k| truth.translation[k] - landed[k]),
        ..truth
    };
    let placed = visible::place(template, centred, centroid, to_model(at), None);
    let off = |p: &Pose| gap(p.translation, truth.translation);
    assert!(
        off(&placed) < 0.5 * off(&centred),
        "{} -> {}",
        off(&centred),
        off(&placed)
    );
    assert_eq!(placed.rotation, centred.rotation);
    // Kept along an axis (a start standing on its plane): moved across it only.
    let x = [1.0, 0.0, 0.0];
    let across = visible::place(template, centred, centroid, to_model(at), Some(x));
    assert_eq!(across.translation[0], centred.translation[0]);
    assert_eq!(&across.translation[1..], &placed.translation[1..]);
    // The grid: about 16 stored points a cell, 4 to 8 cells a side.
    assert_eq!(
        [0, 255, 256, 512, 1024, 4096].map(visible::grid_side),
        [4, 4, 4, 5, 8, 8]
    );
    // Nothing in front of the sensor: left as it was.
    let behind = visible::visible_centroid(template, [0.0, 0.0, 5.0], [0.0, 0.0, 10.0]);
    assert_eq!(behind, None);
    assert_eq!(
        visible::visible_centroid(template, [1.0; 3], [1.0; 3]),
        None
    );
}

#[test]
fn a_view_is_tracked_and_recovered_as_registered_with_it() {
    let model = pcrnet_core::Int8Model::from_bytes(MODEL).unwrap();
    let (source, at, truth) = shipped_view(&model);
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let mut buffer = vec![0f32; view::buffer_len(32)];
    let options = pcrnet_core::Options::default();
    // From the right pose: kept, as `track` keeps it (the view is not needed).
    let kept = model
        .track_view(&source, &truth, at, &options, &mut scratch, &mut buffer)
        .unwrap();
    let plain = model
        .track(&source, &truth, &options, &mut scratch)
        .unwrap();
    assert_eq!(kept.outcome, pcrnet_core::TrackOutcome::Kept);
    assert_eq!(kept, plain);
    // From a pose a half turn away: the step falls back to the
    // registration guided by the view, the same as `register_view`'s.
    let away = Pose {
        rotation: [0.0, 0.0, 1.0, 0.0],
        translation: [0.0; 3],
    };
    let lost = truth.then(&away);
    let fell = model
        .track_view(&source, &lost, at, &options, &mut scratch, &mut buffer)
        .unwrap();
    let viewed = model
        .register_view(&source, at, &options, &mut scratch, &mut buffer)
        .unwrap();
    assert_eq!(fell.outcome, pcrnet_core::TrackOutcome::Recovered);
    assert_eq!(fell.registration, viewed.registration);
    // A viewpoint the view refuses is an error even when the track holds.
    assert!(matches!(
        model.track_view(
            &source,
            &truth,
            source[0],
            &options,
            &mut scratch,
            &mut buffer
        ),
        Err(Error::InvalidOption { .. })
    ));
}

#[test]
fn the_f32_model_tracks_a_view_as_the_int8_one_does() {
    let int8 = pcrnet_core::Int8Model::from_bytes(MODEL).unwrap();
    let (source, at, truth) = shipped_view(&int8);
    let model =
        pcrnet_core::F32Model::from_bytes(include_bytes!("../../models/embedded-default-f32.pcrn"))
            .unwrap();
    let mut scratch = vec![0f32; model.tiled_scratch_len()];
    let mut buffer = vec![0f32; view::buffer_len(32)];
    let options = pcrnet_core::Options::default();
    let kept = model
        .track_view(&source, &truth, at, &options, &mut scratch, &mut buffer)
        .unwrap();
    assert_eq!(kept.outcome, pcrnet_core::TrackOutcome::Kept);
    assert_eq!(
        kept,
        model
            .track(&source, &truth, &options, &mut scratch)
            .unwrap()
    );
    // The source's errors come first, as `register` gives them.
    let mut broken = source.clone();
    broken[2][0] = f32::NAN;
    assert!(matches!(
        model.track_view(
            &broken,
            &truth,
            source[0],
            &options,
            &mut scratch,
            &mut buffer
        ),
        Err(Error::NonFiniteCoordinate { index: 2 })
    ));
}
