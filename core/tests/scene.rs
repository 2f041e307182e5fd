//! The scene stages on generated tabletop depth frames with ground truth:
//! plane, clusters, gathered points, the organised-cloud path, and
//! degenerate frames.

use pcrnet_core::Error;
use pcrnet_core::scene::{
    self, DepthImage, Intrinsics, Organised, OrganisedPoints, PlaneChoice, SceneOptions,
};
use pcrnet_core::testing::scene::{Block, DEPTH_SCALE, Tabletop};

const W: usize = 224;
const H: usize = 172;

const BLOCKS: [Block; 3] = [
    Block {
        at: [-0.2, 0.0],
        size: [0.12, 0.08, 0.15],
        yaw: 0.3,
    },
    Block {
        at: [0.05, 0.1],
        size: [0.1, 0.1, 0.1],
        yaw: -0.6,
    },
    Block {
        at: [0.22, -0.05],
        size: [0.06, 0.14, 0.2],
        yaw: 1.1,
    },
];

fn tabletop(blocks: &[Block], noise: f32) -> Tabletop<'_> {
    Tabletop {
        intrinsics: Tabletop::tof_intrinsics(),
        distance: 0.9,
        pitch: 0.7,
        blocks,
        clouds: &[],
        noise,
        seed: 5,
    }
}

fn render(t: &Tabletop) -> Vec<u16> {
    let mut depth = vec![0u16; W * H];
    t.render(W, H, &mut depth).unwrap();
    depth
}

fn image<'a>(depth: &'a [u16], t: &Tabletop) -> DepthImage<'a> {
    DepthImage::new(depth, W, H, W, t.intrinsics, DEPTH_SCALE, 0).unwrap()
}

fn angle_deg(a: [f32; 3], b: [f32; 3]) -> f32 {
    let c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    c.clamp(-1.0, 1.0).acos().to_degrees()
}

/// The blocks' radii are 0.07 to 0.13 m.
fn options() -> SceneOptions {
    SceneOptions::for_object(0.1)
}

#[test]
fn finds_the_table_within_half_a_degree() {
    let t = tabletop(&BLOCKS, 0.003);
    let depth = render(&t);
    let frame = image(&depth, &t);
    let mut labels = vec![0u16; scene::labels_len(W, H, 4)];
    let s = scene::segment(&frame, &options(), &mut labels).unwrap();
    let plane = s.plane.expect("the table is found");
    let truth = t.table();
    let off = angle_deg(plane.normal, truth.normal);
    assert!(off < 0.5, "normal {off} deg off");
    assert!(
        (plane.offset - truth.offset).abs() < 0.005,
        "{plane:?} vs {truth:?}"
    );
    // Most of the frame is table.
    assert!(s.plane_cells as f32 > 0.5 * s.valid_cells as f32, "{s:?}");
}

#[test]
fn each_block_is_one_kept_cluster() {
    let t = tabletop(&BLOCKS, 0.003);
    let depth = render(&t);
    let frame = image(&depth, &t);
    let o = options();
    let mut labels = vec![0u16; scene::labels_len(W, H, o.step)];
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    assert_eq!(s.clusters.kept.len(), 3, "{:?}", s.clusters);
    for block in &BLOCKS {
        let (base, _, _) = t.placement(block);
        let up = t.up();
        let middle: [f32; 3] = core::array::from_fn(|i| base[i] + up[i] * block.size[2] / 2.0);
        let nearest = s
            .clusters
            .kept
            .iter()
            .map(|c| distance(c.centroid, middle))
            .fold(f32::INFINITY, f32::min);
        // A view sees the near faces: its centroid is off the middle by
        // less than the block's half diagonal.
        let half_diagonal = block.size.iter().map(|s| s * s).sum::<f32>().sqrt() / 2.0;
        assert!(nearest < half_diagonal, "{block:?}: {nearest}");
    }
}

#[test]
fn gathered_points_lie_on_their_block() {
    let blocks = &BLOCKS[1..2];
    let t = tabletop(blocks, 0.0);
    let depth = render(&t);
    let frame = image(&depth, &t);
    let o = options();
    let mut labels = vec![0u16; scene::labels_len(W, H, o.step)];
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    assert_eq!(s.clusters.kept.len(), 1, "{:?}", s.clusters);
    let cluster = s.clusters.kept[0];
    let mut points = vec![[0f32; 3]; 4096];
    let n = s.gather(&frame, &o, &labels, &cluster, &mut points);
    // Full resolution: about step^2 points a cell.
    assert!(
        n as u32 > 8 * cluster.cells,
        "{n} points, {} cells",
        cluster.cells
    );
    let (base, a, b) = t.placement(&blocks[0]);
    let up = t.up();
    let size = blocks[0].size;
    for p in &points[..n] {
        let d: [f32; 3] = core::array::from_fn(|i| p[i] - base[i]);
        let local = [dot(d, a), dot(d, up), dot(d, b)];
        // Inside the block, grown by a millimetre of depth rounding.
        let inside = local[0].abs() <= size[0] / 2.0 + 0.002
            && local[1] >= -0.002
            && local[1] <= size[2] + 0.002
            && local[2].abs() <= size[1] / 2.0 + 0.002;
        assert!(inside, "{p:?} is off the block ({local:?})");
    }
    // A smaller buffer takes every k-th point.
    let mut few = vec![[0f32; 3]; 100];
    let m = s.gather(&frame, &o, &labels, &cluster, &mut few);
    assert!((50..=100).contains(&m), "{m}");
    assert_eq!(few[0], points[0]);
}

#[test]
fn an_organised_cloud_takes_the_same_path_bit_for_bit() {
    let t = tabletop(&BLOCKS, 0.003);
    let depth = render(&t);
    let frame = image(&depth, &t);
    let cloud: Vec<[f32; 3]> = (0..H)
        .flat_map(|v| (0..W).map(move |u| (u, v)))
        .map(|(u, v)| frame.point(u, v).unwrap_or([f32::NAN; 3]))
        .collect();
    let organised = OrganisedPoints::new(&cloud, W).unwrap();
    let o = options();
    let mut a = vec![0u16; scene::labels_len(W, H, o.step)];
    let mut b = a.clone();
    let from_depth = scene::segment(&frame, &o, &mut a).unwrap();
    let from_cloud = scene::segment(&organised, &o, &mut b).unwrap();
    assert_eq!(from_depth, from_cloud);
    assert_eq!(a, b);
}

#[test]
fn a_given_plane_and_a_region_of_interest_are_honoured() {
    let t = tabletop(&BLOCKS, 0.0);
    let depth = render(&t);
    let frame = image(&depth, &t);
    let mut o = options();
    o.plane = PlaneChoice::Given(t.table());
    // Only the right half of the frame (x > 0.1 m).
    o.roi = Some(scene::Region {
        min: [0.1, -5.0, 0.0],
        max: [5.0, 5.0, 5.0],
    });
    let mut labels = vec![0u16; scene::labels_len(W, H, o.step)];
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    assert_eq!(s.plane, Some(t.table()));
    assert_eq!(s.clusters.kept.len(), 1, "{:?}", s.clusters);
    assert!(s.clusters.kept[0].min[0] >= 0.1);
}

#[test]
fn frames_without_objects_give_no_cluster() {
    // A bare table.
    let t = tabletop(&[], 0.003);
    let depth = render(&t);
    let frame = image(&depth, &t);
    let o = options();
    let mut labels = vec![0u16; scene::labels_len(W, H, o.step)];
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    assert!(s.plane.is_some());
    assert!(s.clusters.kept.is_empty(), "{:?}", s.clusters);
    // Nothing seen at all.
    let empty = vec![0u16; W * H];
    let frame = image(&empty, &t);
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    assert_eq!(
        (s.plane, s.valid_cells, s.clusters.foreground),
        (None, 0, 0)
    );
    assert!(s.clusters.kept.is_empty());
    // One pixel.
    let one = [1000u16];
    let frame = DepthImage::new(&one, 1, 1, 1, t.intrinsics, DEPTH_SCALE, 0).unwrap();
    let mut labels = vec![0u16; scene::labels_len(1, 1, 4)];
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    assert_eq!(s.plane, None);
    assert!(s.clusters.kept.is_empty());
}

#[test]
fn bad_frames_and_settings_are_typed_errors() {
    let depth = vec![1000u16; W * H];
    let k = Tabletop::tof_intrinsics();
    let invalid_frame = |r: Result<DepthImage, Error>| {
        assert!(matches!(r, Err(Error::InvalidFrame { .. })), "{r:?}");
    };
    invalid_frame(DepthImage::new(&depth, W, H, W, k, f32::NAN, 0));
    invalid_frame(DepthImage::new(&depth, W, H, W, k, 0.0, 0));
    invalid_frame(DepthImage::new(
        &depth,
        W,
        H,
        W,
        Intrinsics { fx: 0.0, ..k },
        1e-3,
        0,
    ));
    invalid_frame(DepthImage::new(
        &depth,
        W,
        H,
        W,
        Intrinsics {
            cy: f32::INFINITY,
            ..k
        },
        1e-3,
        0,
    ));
    invalid_frame(DepthImage::new(&depth, 0, H, W, k, 1e-3, 0));
    invalid_frame(DepthImage::new(&depth, W, H, W - 1, k, 1e-3, 0));
    invalid_frame(DepthImage::new(&depth[1..], W, H, W, k, 1e-3, 0));
    assert!(OrganisedPoints::new(&[[0.0; 3]; 5], 2).is_err());
    assert!(OrganisedPoints::new(&[], 2).is_err());

    let frame = DepthImage::new(&depth, W, H, W, k, 1e-3, 0).unwrap();
    let mut o = options();
    let mut labels = vec![0u16; scene::labels_len(W, H, o.step)];
    let short = labels.len() - 1;
    assert!(matches!(
        scene::segment(&frame, &o, &mut labels[..short]),
        Err(Error::BufferTooSmall { .. })
    ));
    o.step = 0;
    assert!(matches!(
        scene::segment(&frame, &o, &mut labels),
        Err(Error::InvalidFrame { .. })
    ));
    // 224 x 172 at step 1 is 38,528 cells: fine; 640 x 480 is too many.
    let big = vec![1000u16; 640 * 480];
    let frame = DepthImage::new(&big, 640, 480, 640, k, 1e-3, 0).unwrap();
    o.step = 1;
    let mut labels = vec![0u16; scene::labels_len(640, 480, 1)];
    assert!(matches!(
        scene::segment(&frame, &o, &mut labels),
        Err(Error::InvalidFrame { .. })
    ));
    // A reversed region of interest.
    o.step = 4;
    o.roi = Some(scene::Region {
        min: [1.0; 3],
        max: [0.0; 3],
    });
    assert!(matches!(
        scene::segment(&frame, &o, &mut labels),
        Err(Error::InvalidFrame { .. })
    ));
}

#[test]
fn a_frame_all_one_plane_gives_no_cluster() {
    // A wall facing the camera 1 m away: every pixel at 1000 mm.
    let depth = vec![1000u16; W * H];
    let frame = DepthImage::new(&depth, W, H, W, Tabletop::tof_intrinsics(), 1e-3, 0).unwrap();
    let o = options();
    let mut labels = vec![0u16; scene::labels_len(W, H, o.step)];
    let s = scene::segment(&frame, &o, &mut labels).unwrap();
    let plane = s.plane.expect("the wall is a plane");
    assert!(angle_deg(plane.normal, [0.0, 0.0, -1.0]) < 0.5, "{plane:?}");
    assert_eq!(s.plane_cells, s.valid_cells);
    assert!(s.clusters.kept.is_empty());
}

fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>().sqrt()
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
