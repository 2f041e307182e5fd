//! The whole path from a depth frame to the object's pose on the shipped
//! model: the template's own shape lying on a table under a camera that
//! looks down at it, among blocks, rendered as a 224 x 172 time-of-flight
//! frame (z-buffered splats, millimetre depth, noise).

mod common;

use common::{angle_deg, rotation, template};
use pcrnet_core::locate;
use pcrnet_core::pose::Pose;
use pcrnet_core::scene::{self, DepthImage, SceneOptions};
use pcrnet_core::testing::scene::{Block, DEPTH_SCALE, Placed, Tabletop};
use pcrnet_core::{Int8Model, Options};

const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
const W: usize = 224;
const H: usize = 172;
/// Camera to table, the template's units (the "L" is about 0.8 across).
const DISTANCE: f32 = 2.5;

/// The template turned `deg` about the view axis and lying on a table
/// `DISTANCE` below a camera looking straight down: its largest z (the
/// side away from the camera) on the table, its centre at `(x, y)`.
fn placed(points: &[[f32; 3]], deg: f32, x: f32, y: f32) -> Pose {
    let turn = rotation([0.2, -0.3, 1.0], deg);
    let back = points
        .iter()
        .map(|&p| turn.transform_point(p)[2])
        .fold(f32::NEG_INFINITY, f32::max);
    Pose {
        translation: [x, y, DISTANCE - back],
        ..turn
    }
}

fn render(clouds: &[Placed], blocks: &[Block]) -> Vec<u16> {
    let t = Tabletop {
        intrinsics: Tabletop::tof_intrinsics(),
        distance: DISTANCE,
        pitch: core::f32::consts::FRAC_PI_2,
        blocks,
        clouds,
        noise: 0.002,
        seed: 3,
    };
    let mut depth = vec![0u16; W * H];
    t.render(W, H, &mut depth).unwrap();
    depth
}

struct Found {
    located: locate::Located,
    direct: Option<pcrnet_core::Registration>,
}

fn find(depth: &[u16]) -> Found {
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let mut scratch = vec![0i8; model.scratch_len(1)];
    let frame =
        DepthImage::new(depth, W, H, W, Tabletop::tof_intrinsics(), DEPTH_SCALE, 0).unwrap();
    let scene_options = SceneOptions::for_object(model.object_radius());
    let options = Options::default();
    let mut labels = vec![0u16; scene::labels_len(W, H, scene_options.step)];
    let mut points = vec![[0f32; 3]; 512];
    let located = model
        .locate(
            &frame,
            &scene_options,
            3,
            &options,
            &mut labels,
            &mut points,
            &mut scratch,
        )
        .unwrap();
    // The winner registered on its own: the same pose, bit for bit.
    let direct = located.best.map(|best| {
        let cluster = &located.segmentation.clusters.kept[best.cluster];
        let segmentation = &located.segmentation;
        let n = segmentation.gather(&frame, &scene_options, &labels, cluster, &mut points);
        assert_eq!(n, best.points);
        model
            .register(&points[..n], &options, &mut scratch)
            .unwrap()
    });
    Found { located, direct }
}

#[test]
fn the_object_alone_on_a_table_gives_the_same_pose_as_registering_its_points() {
    let points = template();
    let truth = placed(&points, 20.0, 0.1, -0.05);
    let depth = render(
        &[Placed {
            points: &points,
            pose: truth,
            splat: 0.03,
        }],
        &[],
    );
    let found = find(&depth);
    let best = found.located.best.unwrap();
    assert_eq!(found.located.segmentation.clusters.kept.len(), 1);
    assert_eq!(Some(best.registration), found.direct);
    let verification = best
        .verification
        .expect("a depth image's intrinsics are known");
    assert!(verification.passed && best.reliable, "{verification:?}");
    // registration maps the camera frame onto the template: truth^-1.
    let error = angle_deg(&best.registration.pose, &truth.inverse());
    assert!(error < 5.0, "{error} deg off: {:?}", best.registration);
    assert!(best.registration.reliable);
}

/// Two blocks about the object's size beside where the tests put it.
fn blocks_beside() -> [Block; 2] {
    [
        Block {
            at: [0.9, 0.3],
            size: [0.3, 0.5, 0.4],
            yaw: 0.4,
        },
        Block {
            at: [0.6, -0.6],
            size: [0.5, 0.5, 0.5],
            yaw: 0.0,
        },
    ]
}

#[test]
fn among_blocks_the_object_wins() {
    let points = template();
    let truth = placed(&points, -25.0, -0.2, 0.1);
    let blocks = blocks_beside();
    let depth = render(
        &[Placed {
            points: &points,
            pose: truth,
            splat: 0.03,
        }],
        &blocks,
    );
    let found = find(&depth);
    let located = &found.located;
    let best = located.best.unwrap();
    let error = angle_deg(&best.registration.pose, &truth.inverse());
    assert!(error < 5.0, "{error} deg off: {:?}", best.registration);
    assert!(best.registration.reliable);
    assert!(located.tried.len() >= 2);
    // The blocks' candidates are not the object: their poses put the
    // template where the sensor saw through.
    for c in located.tried.iter().filter(|c| c != &&best) {
        assert!(!c.reliable, "{c:?}");
    }
}

/// Without the object, nothing is reliable: boxes and fragments of the
/// object's size or half of it, whose faces the template's flat sides fit.
#[test]
fn a_frame_without_the_object_is_never_reliable() {
    let mut fits = 0;
    for (i, size) in [
        [0.4f32, 0.35, 0.2],
        [0.8, 0.2, 0.2],
        [0.5, 0.5, 0.1],
        [0.3, 0.3, 0.3],
    ]
    .iter()
    .enumerate()
    {
        let blocks = [Block {
            at: [0.1 * i as f32 - 0.1, 0.05],
            size: *size,
            yaw: 0.5 * i as f32,
        }];
        let depth = render(&[], &blocks);
        let found = find(&depth);
        let located = &found.located;
        for c in &located.tried {
            fits += usize::from(c.registration.reliable);
            assert!(!c.reliable, "block {size:?}: {c:?}");
        }
        assert!(!located.best.is_some_and(|b| b.reliable));
    }
    // The check against the frame is what rejects them: by the residual
    // alone, some of these fit.
    assert!(
        fits >= 1,
        "no block fits by its residual: the test proves nothing"
    );
}

/// One side of the object lying on the table in any yaw: the network's
/// hypotheses do not reach it, the sweep about the table's normal does.
#[test]
fn any_yaw_on_the_table_is_found_by_the_sweep() {
    use pcrnet_core::scene::Plane;
    use pcrnet_core::sweep::Sweep;
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let points = template();
    let table = Plane {
        normal: [0.0, 0.0, -1.0],
        offset: DISTANCE,
    };
    // The template's -z lies along the table's normal when only yawed about z.
    let sweep = Sweep::new(table, [0.0, 0.0, -1.0]);
    let options = Options::default();
    let mut errors = Vec::new();
    for deg in [0.0f32, 70.0, 150.0, 230.0, 310.0] {
        let turn = rotation([0.0, 0.0, 1.0], deg);
        let back = points
            .iter()
            .map(|&p| turn.transform_point(p)[2])
            .fold(f32::NEG_INFINITY, f32::max);
        let truth = Pose {
            translation: [0.1, -0.05, DISTANCE - back],
            ..turn
        };
        let depth = render(
            &[Placed {
                points: &points,
                pose: truth,
                splat: 0.03,
            }],
            &[],
        );
        let frame =
            DepthImage::new(&depth, W, H, W, Tabletop::tof_intrinsics(), DEPTH_SCALE, 0).unwrap();
        let scene_options = SceneOptions::for_object(model.object_radius());
        let mut labels = vec![0u16; scene::labels_len(W, H, scene_options.step)];
        let s = scene::segment(&frame, &scene_options, &mut labels).unwrap();
        let mut view = vec![[0f32; 3]; 512];
        let n = s.gather(
            &frame,
            &scene_options,
            &labels,
            &s.clusters.kept[0],
            &mut view,
        );
        let swept = model
            .register_on_plane(&view[..n], &sweep, &options)
            .unwrap();
        let error = angle_deg(&swept.pose, &truth.inverse());
        errors.push((deg, error, swept.reliable));
    }
    for (deg, error, reliable) in errors {
        assert!(error < 5.0 && reliable, "yaw {deg}: {error} deg off");
    }
}

/// The check judges each template point by where the pose puts it: a pose
/// that leaves more than 5% of the template outside the frame cannot be
/// checked (a cluster cut by the frame's edge), and a point beneath the
/// table the object stands on is a violation (the object cannot be inside
/// it; the sensor sees the table's top, so by depth alone the point would
/// pass as occluded).
#[test]
fn a_pose_out_of_view_or_inside_the_table_fails_the_check() {
    use pcrnet_core::scene::{Plane, VerifySettings, verify::verify};
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let points = template();
    let k = Tabletop::tof_intrinsics();
    let settings = VerifySettings::for_object(model.object_radius());
    let table = Plane {
        normal: [0.0, 0.0, -1.0],
        offset: DISTANCE,
    };
    let check = |depth: &[u16], at: &Pose, surface: Option<Plane>, settings: &VerifySettings| {
        let frame = DepthImage::new(depth, W, H, W, k, DEPTH_SCALE, 0).unwrap();
        // A registration's pose maps the sensor frame onto the template.
        let pose = at.inverse();
        verify(
            &frame,
            &k,
            model.template(),
            model.frame(),
            &pose,
            settings,
            surface,
        )
    };
    let seen = |pose: Pose| {
        render(
            &[Placed {
                points: &points,
                pose,
                splat: 0.03,
            }],
            &[],
        )
    };
    let n = model.template().len() as u32;

    // In view on the table: nothing outside, nothing beneath.
    let truth = placed(&points, 20.0, 0.1, -0.05);
    let depth = seen(truth);
    let right = check(&depth, &truth, Some(table), &settings);
    assert!(right.passed && right.outside == 0, "{right:?}");
    assert_eq!(right, check(&depth, &truth, None, &settings));

    // The object itself at the frame's edge (about 1.44 from the axis at
    // this distance), checked at its true pose: what is in view is seen,
    // but a third or more of it is outside.
    let edge = placed(&points, 20.0, 1.45, -0.05);
    let depth_edge = seen(edge);
    let cut = check(&depth_edge, &edge, Some(table), &settings);
    let total = cut.supported + cut.violations + cut.occluded + cut.unobserved + cut.outside;
    assert_eq!(total, n);
    assert!(cut.outside > n / 4 && !cut.passed, "{cut:?}");
    let lenient = VerifySettings {
        max_outside: 1.0,
        ..settings
    };
    assert!(
        check(&depth_edge, &edge, Some(table), &lenient).passed,
        "only the share outside fails it: {cut:?}"
    );

    // Sunk into the table by a fifth of the object's radius.
    let sink = 0.2 * model.object_radius();
    let sunk = Pose {
        translation: [
            truth.translation[0],
            truth.translation[1],
            truth.translation[2] + sink,
        ],
        ..truth
    };
    let beneath = (0..model.template().len())
        .map(|i| sunk.transform_point(model.template().user_point(i, model.frame())))
        .filter(|p| p[2] > DISTANCE + settings.tolerance)
        .count() as u32;
    assert!(
        beneath > n / 10,
        "{beneath} of {n} beneath: the test proves nothing"
    );
    let with = check(&depth, &sunk, Some(table), &settings);
    let without = check(&depth, &sunk, None, &settings);
    assert!(with.violations >= beneath && !with.passed, "{with:?}");
    assert!(with.violations > without.violations, "{with:?} {without:?}");
    assert!(with.occluded < without.occluded, "{with:?} {without:?}");
}

/// Following the object into the next frame: moved and turned 6°, among
/// blocks that reach into the box about it, it is found again by ICP from
/// the last pose (the cluster nearest where it was), reliable and within
/// 2° of where it now stands; in a frame
/// without it nothing reliable is found; a pose that is not a unit
/// rotation is refused.
#[test]
fn the_next_frame_is_followed_from_the_last_pose() {
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let points = template();
    let first = placed(&points, -25.0, -0.2, 0.1);
    let splat = |pose| Placed {
        points: &points,
        pose,
        splat: 0.03,
    };
    let block = blocks_beside();
    let found = find(&render(&[splat(first)], &block));
    let best = found.located.best.unwrap();
    assert!(best.reliable);
    let plane = found.located.segmentation.plane;
    assert!(plane.is_some());

    let moved = placed(&points, -19.0, -0.17, 0.1);
    let depth = render(&[splat(moved)], &block);
    let scene_options = SceneOptions::for_object(model.object_radius());
    let mut labels = vec![0u16; scene::labels_len(W, H, scene_options.step)];
    let mut cloud = vec![[0f32; 3]; 512];
    let mut scratch = vec![0i8; model.scratch_len(1)];
    let options = Options::default();
    let mut follow = |depth: &[u16], previous: &Pose| {
        let frame =
            DepthImage::new(depth, W, H, W, Tabletop::tof_intrinsics(), DEPTH_SCALE, 0).unwrap();
        model.follow(
            &frame,
            &scene_options,
            previous,
            plane,
            &options,
            &mut labels,
            &mut cloud,
            &mut scratch,
        )
    };
    let followed = follow(&depth, &best.registration.pose).unwrap();
    let next = followed.best.unwrap();
    assert_eq!(followed.tried.len(), 1);
    assert!(next.reliable, "{next:?}");
    let error = angle_deg(&next.registration.pose, &moved.inverse());
    assert!(error < 2.0, "{error} deg off: {next:?}");
    // The box about the last pose held pieces of the blocks too.
    let kept = &followed.segmentation.clusters.kept;
    assert!(kept.len() >= 2, "{kept:?}");

    // The object gone: nothing reliable.
    let empty = render(&[], &block);
    let gone = follow(&empty, &next.registration.pose).unwrap();
    assert!(!gone.best.is_some_and(|b| b.reliable), "{gone:?}");
    // A pose that is not a rotation.
    let bad = Pose {
        rotation: [2.0, 0.0, 0.0, 0.0],
        ..next.registration.pose
    };
    assert_eq!(
        follow(&depth, &bad).err(),
        Some(pcrnet_core::Error::InvalidPose)
    );
}
