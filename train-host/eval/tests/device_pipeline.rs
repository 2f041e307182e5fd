//! The device pipeline with the shipped model (`models/`, in the
//! repository): frames round-trip between units, a known transform is
//! recovered, and degenerate or hostile sources give a typed error or a
//! flagged result, never NaN or a runaway pose.

use std::path::PathBuf;

use pcrnet_core::{Degeneracy, Error, Int8Model, MAX_TILE, Options, Registration};
use pcrnet_eval::register::{Bound, pipeline};
use pcrnet_train::shapes::{Shape, random_transform, sample};
use pcrnet_train::template::TemplateError;

fn shipped() -> Vec<u8> {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models/embedded-default-int8.pcrn");
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The angle between two rotations (unit quaternions), in degrees:
/// `4 atan2(|a - s b|, |a + s b|)` in f64 with `s` the sign of `a . b`,
/// accurate near 0 where `2 acos(|a . b|)` in f32 resolves only about
/// 0.03 degrees.
fn angle_deg(a: &[f32; 4], b: &[f32; 4]) -> f32 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum();
    let s = if d < 0.0 { -1.0 } else { 1.0 };
    let norm = |sign: f64| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (*x as f64 - sign * s * *y as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    (4.0 * norm(1.0).atan2(norm(-1.0))).to_degrees() as f32
}

fn register(template: &[[f32; 3]], source: &[[f32; 3]]) -> Result<Registration, TemplateError> {
    pipeline(
        &shipped(),
        Some(Bound::new(template)),
        source,
        &Options::default(),
    )
    .map(|(r, _)| r)
}

#[test]
fn a_known_transform_is_recovered_in_any_unit_and_place() {
    let unit = sample(Shape::Ell, 512, 11);
    let source_unit = random_transform(&unit, 30.0, 0.3, 12);
    // The same scene in metres near the origin, and in millimetres 2 km away.
    let metres = |p: &[f32; 3]| p.map(|v| v * 0.4);
    let far_mm = |p: &[f32; 3]| [p[0] * 400.0 + 2.0e6, p[1] * 400.0 - 5.0e5, p[2] * 400.0];
    let (tm, sm): (Vec<_>, Vec<_>) = (
        unit.iter().map(metres).collect(),
        source_unit.iter().map(metres).collect(),
    );
    let (tf, sf): (Vec<_>, Vec<_>) = (
        unit.iter().map(far_mm).collect(),
        source_unit.iter().map(far_mm).collect(),
    );
    let m = register(&tm, &sm).unwrap();
    let f = register(&tf, &sf).unwrap();
    assert!(m.reliable && f.reliable, "{m:?} {f:?}");
    // The source is the template moved: every point lands back (< 0.1 degree
    // at the object's size, 0.4 m: 0.7 mm).
    for (s, t) in sm.iter().zip(&tm) {
        let p = m.pose.transform_point(*s);
        let d = ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2) + (p[2] - t[2]).powi(2)).sqrt();
        assert!(d < 7e-4, "{d} m: {m:?}");
    }
    // Same rotation in both frames; the residual scales with the unit.
    assert!(
        angle_deg(&m.pose.rotation, &f.pose.rotation) < 0.05,
        "{m:?} {f:?}"
    );
    assert!((m.relative_residual - f.relative_residual).abs() < 1e-3);
    assert!(f.residual < 1.0, "{f:?} (millimetres)");
}

#[test]
fn degenerate_and_hostile_sources_are_errors_or_flagged() {
    let template = sample(Shape::Ell, 512, 13);
    let blob = shipped();
    let model = Int8Model::from_bytes(&blob).unwrap();
    let extent = 1.0f32;
    let check = |name: &str, source: &[[f32; 3]]| -> Result<Registration, Error> {
        let r = pipeline(
            &blob,
            Some(Bound::new(&template)),
            source,
            &Options::default(),
        );
        match r {
            Ok((r, _)) => {
                let values = r.pose.rotation.iter().chain(&r.pose.translation);
                assert!(values.clone().all(|v| v.is_finite()), "{name}: {r:?}");
                let t = r.pose.translation;
                let size = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
                assert!(size < 100.0 * extent, "{name}: runaway translation {r:?}");
                assert!(r.residual.is_finite() && r.fitness.is_finite(), "{name}");
                Ok(r)
            }
            Err(TemplateError::Core(e)) => Err(e),
            Err(e) => panic!("{name}: {e}"),
        }
    };
    let one = check("one point", &[[0.1, 0.2, 0.3]]).unwrap();
    assert_eq!(one.degenerate, Some(Degeneracy::Point));
    assert!(!one.reliable);
    let same = check("all equal", &[[0.3, -0.2, 0.1]; 50]).unwrap();
    assert_eq!(same.degenerate, Some(Degeneracy::Point));
    assert!(!same.reliable);
    let line: Vec<[f32; 3]> = (0..60).map(|i| [i as f32 / 60.0 - 0.5, 0.1, 0.2]).collect();
    let line = check("collinear", &line).unwrap();
    assert_eq!(line.degenerate, Some(Degeneracy::Line));
    assert!(!line.reliable);
    // A planar patch determines a pose up to its own symmetries: not
    // degenerate, judged by its residual.
    let plane: Vec<[f32; 3]> = (0..400)
        .map(|i| {
            [
                (i % 20) as f32 / 20.0 - 0.5,
                (i / 20) as f32 / 20.0 - 0.5,
                0.0,
            ]
        })
        .collect();
    assert_eq!(check("planar", &plane).unwrap().degenerate, None);
    // Stray points far away (issue 10, item 7): left out of the network
    // and of the centring, counted, and the pose is the clean cloud's.
    // Both lie where the network's sample takes them (every k-th point at
    // the default `network_points`).
    let clean = random_transform(&template, 20.0, 0.1, 3);
    let k = (clean.len() + 2).div_ceil(Options::default().network_points);
    let mut stray = clean.clone();
    stray.insert(20 * k, [40.0, 0.0, 0.0]);
    stray.insert(100 * k, [1e9, -1e9, 5.0]);
    let sampled = Options::default()
        .network_sample(&stray)
        .filter(|p| p[0] >= 40.0)
        .count();
    assert_eq!(sampled, 2);
    let (with, without) = (
        check("outliers", &stray).unwrap(),
        check("clean", &clean).unwrap(),
    );
    assert_eq!((with.out_of_range, without.out_of_range), (2, 0));
    assert!(with.reliable && without.reliable);
    let (a, b) = (with.pose.rotation, without.pose.rotation);
    let dot: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let angle = 2.0 * dot.abs().min(1.0).acos().to_degrees();
    assert!(
        angle < 0.5,
        "the outliers moved the pose by {angle} degrees"
    );
    // Every point far away: no pose, and the error says why.
    let far = [
        [40.0, 0.0, 0.0],
        [-40.0, 0.0, 0.0],
        [0.0, 40.0, 0.0],
        [0.0, -40.0, 0.0],
    ];
    assert_eq!(check("far", &far).unwrap_err(), Error::NoPointInRange);
    // Finite but huge coordinates: an error, not an infinite pose.
    let huge = [
        [3e38f32, 3e38, 3e38],
        [-3e38, -3e38, -3e38],
        [3e38, -3e38, 0.0],
    ];
    assert!(check("huge", &huge).is_err());
    assert_eq!(check("empty", &[]).unwrap_err(), Error::EmptyCloud);
    let nan = [[0.0, f32::NAN, 0.0]];
    assert_eq!(
        check("NaN", &nan).unwrap_err(),
        Error::NonFiniteCoordinate { index: 0 }
    );
    // Bad options are typed errors too.
    let mut scratch = vec![0i8; model.scratch_len(MAX_TILE)];
    let zero = Options {
        passes: 0,
        ..Options::default()
    };
    assert!(matches!(
        model.register(&template, &zero, &mut scratch),
        Err(Error::InvalidOption { .. })
    ));
}

#[test]
fn sources_sampled_apart_from_the_template_are_judged_by_the_plane_residual() {
    // Template and source sampled independently from the same surface, as
    // a sensor samples it: no point shared.
    let template = sample(Shape::Ell, 512, 21);
    let source = random_transform(&sample(Shape::Ell, 512, 22), 30.0, 0.3, 23);
    let r = register(&template, &source).unwrap();
    // The point-to-point residual carries the gap between the samplings;
    // the plane residual does not, and the verdict uses it.
    assert!(
        r.relative_plane_residual < 0.5 * r.relative_residual,
        "{r:?}"
    );
    assert!(r.reliable, "{r:?}");
    // A different object scored against this template is not trusted.
    let torus = random_transform(&sample(Shape::Torus, 512, 24), 30.0, 0.3, 25);
    let wrong = register(&template, &torus).unwrap();
    assert!(!wrong.reliable, "{wrong:?}");
    assert!(wrong.relative_plane_residual > 2.0 * r.relative_plane_residual);
}

/// Issue 10, item 8: inside the accepted input range, a cloud larger than
/// the calibration saw clips int8 activations, and the int8 pose can part
/// from the f32 one. The result says so: `saturated` counts the clipped
/// values (0 at the template's size), and such a cloud is not reliable.
#[test]
fn a_cloud_larger_than_calibrated_is_flagged() {
    let blob = shipped();
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models/embedded-default-source.xyz");
    let source = pcrnet_io::read_cloud(&path).unwrap();
    let centre = pcrnet_core::pose::centroid(&source).unwrap();
    let scaled = |s: f32| -> Vec<[f32; 3]> {
        source
            .iter()
            .map(|p| [0, 1, 2].map(|k| centre[k] + s * (p[k] - centre[k])))
            .collect()
    };
    let run = |s: f32| {
        pipeline(&blob, None, &scaled(s), &Options::default())
            .unwrap()
            .0
    };
    let (one, big) = (run(1.0), run(2.5));
    assert_eq!(one.saturated, 0);
    assert!(one.reliable);
    assert!(big.saturated > 0, "{big:?}");
    assert!(!big.reliable);
}

/// A cloud registered onto itself (bound as the template) comes back as
/// the identity with a residual near zero, and is reliable. Four points,
/// (0,0,0), (1,0,0), (0,1,0), (0,0,1), give point-to-plane ICP four
/// equations for six unknowns, so it keeps the network's pose and flags
/// it; point-to-point ICP matches the four exactly.
#[test]
fn a_cloud_onto_itself_is_the_identity() {
    let cloud = sample(Shape::Ell, 512, 21);
    let r = register(&cloud, &cloud).unwrap();
    let identity = [1.0, 0.0, 0.0, 0.0];
    assert!(r.reliable, "{r:?}");
    assert!(angle_deg(&r.pose.rotation, &identity) < 0.1, "{r:?}");
    assert!(r.relative_residual < 1e-4, "{r:?}");
    let four = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let plane = register(&four, &four).unwrap();
    assert!(!plane.reliable, "{plane:?}");
    let point = Options {
        metric: pcrnet_core::refine::Metric::PointToPoint,
        ..Options::default()
    };
    let (r, _) = pipeline(&shipped(), Some(Bound::new(&four)), &four, &point).unwrap();
    assert!(r.reliable, "{r:?}");
    assert!(angle_deg(&r.pose.rotation, &identity) < 0.1, "{r:?}");
    assert!(r.relative_residual < 1e-4, "{r:?}");
}

/// The template's stored feature is the feature a registration compares
/// with: the template itself at its true pose lies at (near) zero feature
/// distance (0.112 when the exporter centred the sample on its own
/// centroid instead of the whole template's). Catches a
/// template feature pooled or centred unlike a source (the shipped model
/// centres its sources; templates here have more points than the
/// network's sample).
#[test]
fn a_template_at_its_own_pose_is_at_zero_feature_distance() {
    let template = sample(Shape::Ell, 600, 21);
    let bound = pcrnet_train::template::bind(&shipped(), &template, 512).unwrap();
    let model = Int8Model::from_bytes(&bound).unwrap();
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let d = model
        .feature_distance(&template, &pcrnet_core::Pose::IDENTITY, &mut scratch)
        .unwrap();
    assert!(d < 1e-3, "feature distance {d}");
}
