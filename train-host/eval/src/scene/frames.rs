//! The scene experiment's frames: a ModelNet10 shape standing on a table
//! among distractors, rendered for a camera with and without it
//! ([`generate`]), and a picture of what `locate` made of one ([`picture`]).

use std::path::Path;

use pcrnet_core::Pose;
use pcrnet_core::scene::{self, DepthImage, Intrinsics, SceneOptions};
use pcrnet_core::testing::scene::{Block, DEPTH_SCALE, Placed, Tabletop};
use pcrnet_train::dataset::Dataset;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::sensor::Artifacts;

/// A simulated depth camera.
#[derive(Debug, Clone, Copy)]
pub struct Camera {
    /// Its name in the report.
    pub name: &'static str,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// Distance to the table along the optical axis, metres: U[lo, hi].
    pub distance: [f32; 2],
    /// What it does at depth edges.
    pub artifacts: Artifacts,
}

/// The cameras: a 224 x 172 time-of-flight sensor (about 60 x 48 degrees)
/// with flying pixels at depth edges, and a 640 x 480 structured-light
/// RGB-D camera (about 63 x 49 degrees, a Kinect's) with missing pixels
/// there ([`super::sensor`]).
pub const CAMERAS: [Camera; 2] = [
    Camera {
        name: "ToF 224 x 172",
        width: 224,
        height: 172,
        intrinsics: Intrinsics {
            fx: 194.0,
            fy: 194.0,
            cx: 111.5,
            cy: 85.5,
        },
        distance: [0.7, 1.1],
        artifacts: Artifacts::TimeOfFlight {
            flying: 0.5,
            dropped: 0.2,
        },
    },
    Camera {
        name: "RGB-D 640 x 480",
        width: 640,
        height: 480,
        intrinsics: Intrinsics {
            fx: 525.0,
            fy: 525.0,
            cx: 319.5,
            cy: 239.5,
        },
        distance: [1.0, 1.6],
        // A Kinect's projector 7.5 cm beside its camera: an edge 10 cm in
        // front of what is behind it, at 1.2 m, shadows about 3 pixels.
        artifacts: Artifacts::StructuredLight {
            dropped: 0.5,
            shadow: 3,
        },
    },
];

/// One generated scene.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The shape's path below the data root.
    pub shape: String,
    /// Its template (scaled, 512 points, its own frame).
    pub template: Vec<[f32; 3]>,
    /// The pose a registration should return: camera frame -> template.
    pub truth: Pose,
    /// The frame with the object (millimetres, row order).
    pub present: Vec<u16>,
    /// The same scene without it.
    pub absent: Vec<u16>,
    /// The next frame: the object moved a little ([`MOVE_METRES`],
    /// [`MOVE_DEGREES`]).
    pub moved: Vec<u16>,
    /// The pose a registration of `moved` should return.
    pub moved_truth: Pose,
    /// The frames after `present` in a stream ([`STREAM_FRAMES`]): the
    /// object turning in place, each with the pose a registration should
    /// return.
    pub stream: Vec<(Vec<u16>, Pose)>,
}

/// Frames of a stream after the first.
pub const STREAM_FRAMES: usize = 8;
/// How far the object turns between two frames of a stream (degrees,
/// uniform): a turntable at 30 to 75 degrees a second at 15 frames a second.
pub const STREAM_DEGREES: [f32; 2] = [2.0, 5.0];
/// How far each frame of a stream puts it from where it first stood
/// along the table, at most (metres, uniform in each axis).
pub const STREAM_JITTER: f32 = 0.005;

/// How far the object slides along the table between two frames, at most
/// (metres): 2 cm, 0.6 m/s at 30 frames a second.
pub const MOVE_METRES: f32 = 0.02;
/// How far it turns about the table's normal, at most (degrees).
pub const MOVE_DEGREES: f32 = 5.0;

/// `points` scaled by `s`.
fn scaled(points: &[[f32; 3]], s: f32) -> Vec<[f32; 3]> {
    points.iter().map(|p| p.map(|v| v * s)).collect()
}

/// The largest distance of `points` from the origin.
fn radius_of(points: &[[f32; 3]]) -> f32 {
    points
        .iter()
        .map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
        .fold(0.0, f32::max)
}

/// Shape `i`'s points (template and rest) scaled to `radius`, and the scale.
fn shape_points(shapes: &Dataset, i: usize, radius: f32) -> (Vec<[f32; 3]>, f32) {
    let s = radius / radius_of(&shapes.clouds[i]).max(1e-6);
    let mut all = scaled(&shapes.clouds[i], s);
    all.extend(scaled(&shapes.rest[i], s));
    (all, s)
}

/// The scene of `seed` for `camera`: a seeded shape of `shapes` scaled to
/// `radius` standing on the table in a random yaw, 2 to 5 distractors.
pub fn generate(
    shapes: &Dataset,
    camera: &Camera,
    seed: u64,
    radius: f32,
) -> anyhow::Result<Generated> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let i = rng.random_range(0..shapes.clouds.len());
    let (object, s) = shape_points(shapes, i, radius);
    let template = scaled(&shapes.clouds[i], s);
    let t = Tabletop {
        intrinsics: camera.intrinsics,
        distance: rng.random_range(camera.distance[0]..camera.distance[1]),
        pitch: rng.random_range(35f32..65.0).to_radians(),
        blocks: &[],
        clouds: &[],
        noise: 0.004,
        seed,
    };
    let up = [0.0, 0.0, 1.0];
    let at = [rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1)];
    let yaw = rng.random_range(0.0..std::f32::consts::TAU);
    let pose = t.stand(&object, up, at, yaw);
    // Distractors: (where, radius), boxes and other classes' shapes.
    let mut taken: Vec<([f32; 2], f32)> = vec![(at, radius)];
    let mut blocks = Vec::new();
    let mut others: Vec<(Vec<[f32; 3]>, Pose, f32)> = Vec::new();
    let count = rng.random_range(2..=5);
    for _ in 0..count {
        let is_box = rng.random_bool(0.5);
        let (size, r) = if is_box {
            let size = [(); 3].map(|_| rng.random_range(0.05f32..0.2));
            let r = (size[0] * size[0] + size[1] * size[1] + size[2] * size[2]).sqrt() / 2.0;
            (size, r)
        } else {
            let r = rng.random_range(0.08f32..0.18);
            ([0.0; 3], r)
        };
        let place = (0..50).find_map(|_| {
            let p = [rng.random_range(-0.45..0.45), rng.random_range(-0.3..0.45)];
            let clear = taken.iter().all(|(q, rq)| {
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
                d > r + rq + 0.03
            });
            clear.then_some(p)
        });
        let Some(p) = place else {
            continue;
        };
        taken.push((p, r));
        let yaw = rng.random_range(0.0..std::f32::consts::TAU);
        if is_box {
            blocks.push(Block { at: p, size, yaw });
        } else {
            let label = &shapes.labels[i];
            let choices: Vec<usize> = (0..shapes.clouds.len())
                .filter(|&k| &shapes.labels[k] != label)
                .collect();
            let k = choices[rng.random_range(0..choices.len())];
            let (points, _) = shape_points(shapes, k, r);
            let pose = t.stand(&points, up, p, yaw);
            others.push((points, pose, r));
        }
    }
    let splat = |r: f32| 0.08 * r;
    let mut clouds: Vec<Placed> = others
        .iter()
        .map(|(points, pose, r)| Placed {
            points,
            pose: *pose,
            splat: splat(*r),
        })
        .collect();
    let render = |clouds: &[Placed]| -> anyhow::Result<Vec<u16>> {
        let mut depth = vec![0u16; camera.width * camera.height];
        Tabletop {
            blocks: &blocks,
            clouds,
            ..t
        }
        .render(camera.width, camera.height, &mut depth)?;
        let (w, h) = (camera.width, camera.height);
        super::sensor::apply(&mut depth, w, h, DEPTH_SCALE, camera.artifacts, seed);
        Ok(depth)
    };
    let absent = render(&clouds)?;
    clouds.push(Placed {
        points: &object,
        pose,
        splat: splat(radius),
    });
    let present = render(&clouds)?;
    // The next frame of a stream: the object slid up to MOVE_METRES along
    // the table and turned up to MOVE_DEGREES about its normal.
    let (angle, reach) = (
        rng.random_range(0.0..std::f32::consts::TAU),
        rng.random_range(0.0..MOVE_METRES),
    );
    let turn = rng.random_range(-MOVE_DEGREES..MOVE_DEGREES).to_radians();
    let later = [at[0] + reach * angle.cos(), at[1] + reach * angle.sin()];
    let moved_pose = t.stand(&object, up, later, yaw + turn);
    if let Some(last) = clouds.last_mut() {
        last.pose = moved_pose;
    }
    let moved = render(&clouds)?;
    // A stream from the first frame on: the object turning in place, as on
    // a turntable, with a few millimetres of jitter along the table.
    let mut stream = Vec::with_capacity(STREAM_FRAMES);
    let mut turned = yaw;
    for _ in 0..STREAM_FRAMES {
        turned += rng
            .random_range(STREAM_DEGREES[0]..STREAM_DEGREES[1])
            .to_radians();
        let j = STREAM_JITTER;
        let place = [
            at[0] + rng.random_range(-j..j),
            at[1] + rng.random_range(-j..j),
        ];
        let pose = t.stand(&object, up, place, turned);
        if let Some(last) = clouds.last_mut() {
            last.pose = pose;
        }
        stream.push((render(&clouds)?, pose.inverse()));
    }
    Ok(Generated {
        shape: shapes.names[i].clone(),
        template,
        truth: pose.inverse(),
        present,
        absent,
        moved,
        moved_truth: moved_pose.inverse(),
        stream,
    })
}

/// Writes a picture of `g`'s frame with the object: depth in grey, the
/// kept clusters tinted, the template drawn in red where the winning pose
/// puts it (the sweep).
pub fn picture(
    model: &pcrnet_core::Int8Model,
    camera: &Camera,
    g: &Generated,
    path: &Path,
) -> anyhow::Result<()> {
    let (w, h) = (camera.width, camera.height);
    let image = DepthImage::new(&g.present, w, h, w, camera.intrinsics, DEPTH_SCALE, 0)?;
    let options = SceneOptions {
        up: Some([0.0, 0.0, 1.0]),
        ..SceneOptions::for_object(model.object_radius())
    };
    let mut labels = vec![0u16; scene::labels_len(w, h, options.step)];
    let mut points = vec![[0f32; 3]; 512];
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let located = model.locate(
        &image,
        &options,
        3,
        &pcrnet_core::Options::default(),
        &mut labels,
        &mut points,
        &mut scratch,
    )?;
    let (near, far) = g
        .present
        .iter()
        .filter(|&&d| d > 0)
        .fold((u16::MAX, 0), |(a, b), &d| (a.min(d), b.max(d)));
    let span = f32::from(far.saturating_sub(near).max(1));
    let mut rgb = vec![0u8; 3 * w * h];
    let step = options.step;
    let columns = w.div_ceil(step);
    let tints = [
        [80u8, 160, 255],
        [80, 220, 120],
        [240, 200, 60],
        [200, 120, 240],
    ];
    for v in 0..h {
        for u in 0..w {
            let d = g.present[v * w + u];
            let grey = if d == 0 {
                0
            } else {
                (230.0 - 180.0 * f32::from(d - near) / span) as u8
            };
            let mut c = [grey; 3];
            let label = labels[(v / step) * columns + u / step];
            if let Some(k) = located
                .segmentation
                .clusters
                .kept
                .iter()
                .position(|k| k.label == label)
            {
                let t = tints[k % tints.len()];
                c = [0, 1, 2].map(|i| ((u16::from(c[i]) + u16::from(t[i])) / 2) as u8);
            }
            rgb[3 * (v * w + u)..3 * (v * w + u) + 3].copy_from_slice(&c);
        }
    }
    if let Some(best) = &located.best {
        let back = best.registration.pose.inverse();
        for &p in &g.template {
            let q = back.transform_point(p);
            if let Some(([pu, pv], _)) = pcrnet_core::scene::depth::project(&camera.intrinsics, q) {
                let (u, v) = (pu.round(), pv.round());
                if u >= 0.0 && v >= 0.0 && (u as usize) < w && (v as usize) < h {
                    let at = 3 * (v as usize * w + u as usize);
                    rgb[at..at + 3].copy_from_slice(&[255, 40, 40]);
                }
            }
        }
    }
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, w as u32, h as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&rgb)?;
    writer.finish()?;
    Ok(())
}
