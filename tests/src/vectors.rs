//! Test models, clouds and the container the device reads.

use pcrnet_core::testing::{SplitMix64, random_int8_blob_with, with_random_lk_solver};
use pcrnet_core::{Frame, Int8Model, Metric, Options, POSE_DIM, Registration};

/// Container format version (the device checks it).
pub const CONTAINER_VERSION: u32 = 5;
/// Scratch bytes on the device (and lent to the host's `register`, so both
/// pick the same tile).
pub const SCRATCH_LEN: usize = 64 * 1024;
/// u32 words per case in the container's table.
const CASE_WORDS: usize = 7;
/// u32 words per [`Options`] in the container.
pub const OPTIONS_WORDS: usize = 13;

/// A named int8 model blob.
pub struct TestModel {
    /// Human-readable name.
    pub name: String,
    /// The blob.
    pub blob: Vec<u8>,
}

/// One case: a cloud run through one model with one tile size.
pub struct Case {
    /// Index into the models.
    pub model: usize,
    /// What the cloud is (for reports).
    pub label: String,
    /// The points.
    pub cloud: Vec<[f32; 3]>,
    /// Tile size passed to the encoder.
    pub tile: usize,
    /// i-PCRNet passes to run as well (0: none), with tolerance 0.
    pub iterations: usize,
    /// `Int8Model::register` runs, one per option set (none: not registered).
    pub registrations: Vec<Options>,
}

/// A registration's outputs in comparable form: every f32 as its bits.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RegistrationBits {
    /// Pose bits `[qw, qx, qy, qz, tx, ty, tz]`.
    pub pose: [u32; POSE_DIM],
    /// `residual` bits.
    pub residual: u32,
    /// `relative_residual` bits.
    pub relative_residual: u32,
    /// `fitness` bits.
    pub fitness: u32,
    /// `inlier_rmse` bits.
    pub inlier_rmse: u32,
    /// `plane_residual` bits.
    pub plane_residual: u32,
    /// `relative_plane_residual` bits.
    pub relative_plane_residual: u32,
    /// Winning hypothesis.
    pub hypothesis: usize,
    /// Network passes run.
    pub passes: usize,
    /// PointNetLK steps run after them.
    pub lk_iterations: usize,
    /// ICP iterations run from the winning start.
    pub icp_iterations: usize,
    /// Saturated int8 values.
    pub saturated: u32,
    /// Points outside the input range, left out of the network.
    pub out_of_range: u32,
    /// `none`, or the `Degeneracy` variant's name (`Point`, `Line`).
    pub degenerate: String,
    /// Whether the pose is reliable.
    pub reliable: bool,
    /// The ambiguity as two words ([`pcrnet_core::testing::describe_ambiguity`]).
    pub ambiguity: String,
}

impl From<&Registration> for RegistrationBits {
    fn from(r: &Registration) -> Self {
        RegistrationBits {
            pose: pose_bits(&r.pose),
            residual: r.residual.to_bits(),
            relative_residual: r.relative_residual.to_bits(),
            fitness: r.fitness.to_bits(),
            inlier_rmse: r.inlier_rmse.to_bits(),
            plane_residual: r.plane_residual.to_bits(),
            relative_plane_residual: r.relative_plane_residual.to_bits(),
            hypothesis: r.hypothesis,
            passes: r.passes,
            lk_iterations: r.lk_iterations,
            icp_iterations: r.icp_iterations,
            saturated: r.saturated,
            out_of_range: r.out_of_range,
            degenerate: r
                .degenerate
                .map_or_else(|| "none".to_string(), |d| format!("{d:?}")),
            reliable: r.reliable,
            ambiguity: {
                let mut words = String::new();
                // Writing into a String cannot fail.
                let _ = pcrnet_core::testing::describe_ambiguity(&r.ambiguity, &mut words);
                words
            },
        }
    }
}

/// Result of one `register` call: its outputs, or the error's Debug text.
pub type RegistrationOutcome = Result<RegistrationBits, String>;

/// An error's Debug text as the device's line carries it (words separated by one space).
pub fn error_text(e: &pcrnet_core::Error) -> String {
    format!("{e:?}")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// What the host computes for each of a case's registrations, in order.
pub fn expected_registrations(model: &[u8], case: &Case) -> Vec<RegistrationOutcome> {
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    let mut scratch = vec![0i8; SCRATCH_LEN];
    case.registrations
        .iter()
        .map(|o| {
            m.register(&case.cloud, o, &mut scratch)
                .map(|r| RegistrationBits::from(&r))
                .map_err(|e| error_text(&e))
        })
        .collect()
}

/// `n` and `noun`, plural unless `n` is 1 (`1 pass`, `3 LK steps`).
fn count(n: usize, noun: &str) -> String {
    match (n, noun.ends_with('s')) {
        (1, _) => format!("1 {noun}"),
        (_, true) => format!("{n} {noun}es"),
        (_, false) => format!("{n} {noun}s"),
    }
}

/// A short name for a set of options (reports).
pub fn describe(o: &Options) -> String {
    let d = Options::default();
    if *o == Options::network_only() {
        return "network only".into();
    }
    if *o == d {
        return format!("default (K={}, ICP {})", o.hypotheses, o.icp_iterations);
    }
    if *o
        == (Options {
            hypotheses: o.hypotheses,
            ..d
        })
    {
        return format!("K={} + ICP {}", o.hypotheses, o.icp_iterations);
    }
    if *o
        == (Options {
            passes: 0,
            lk_iterations: o.lk_iterations,
            ..Options::network_only()
        })
    {
        return format!("LK only ({})", count(o.lk_iterations, "step"));
    }
    if *o
        == (Options {
            passes: o.passes,
            lk_iterations: o.lk_iterations,
            ..d
        })
    {
        return format!(
            "{} + {} + K={} + ICP {}",
            count(o.passes, "pass"),
            count(o.lk_iterations, "LK step"),
            o.hypotheses,
            o.icp_iterations
        );
    }
    let lk = if o.lk_iterations > 0 {
        format!(" + {}", count(o.lk_iterations, "LK step"))
    } else {
        String::new()
    };
    format!(
        "{} passes{lk} (tol {}), K={}, ICP {} {:?} (screen {}, tol {}, {}), inlier {}, {} points, max residual {}",
        o.passes,
        o.tolerance,
        o.hypotheses,
        o.icp_iterations,
        o.metric,
        o.screen_iterations,
        o.icp_tolerance,
        o.icp_distance,
        o.inlier_distance,
        o.max_points,
        o.max_residual
    )
}

/// Result of an iterative registration: passes done and pose bits, or the error's Debug text.
pub type Iterative = Result<(usize, [u32; POSE_DIM]), String>;

fn pose_bits(p: &pcrnet_core::Pose) -> [u32; POSE_DIM] {
    let mut bits = [0u32; POSE_DIM];
    for (b, v) in bits.iter_mut().zip(p.rotation.iter().chain(&p.translation)) {
        *b = v.to_bits();
    }
    bits
}

/// What the host computes for a case's iterative registration, if it has one.
pub fn expected_iterative(model: &[u8], case: &Case) -> Option<Iterative> {
    if case.iterations == 0 {
        return None;
    }
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    // The host's fastest kernels (the x86-64 block kernel where it runs).
    let mut scratch = vec![0i8; m.host_scratch_len()];
    Some(
        m.network_pose(&case.cloud, case.iterations, 0.0, &mut scratch)
            .map(|(p, n)| (n, pose_bits(&p)))
            .map_err(|e| error_text(&e)),
    )
}

/// What the host computes for a case, in the device's terms.
#[derive(Debug, Clone, PartialEq)]
pub enum Expected {
    /// Inference succeeded.
    Ok {
        /// int8 feature.
        feature: Vec<i8>,
        /// Raw head accumulators.
        head: [i32; POSE_DIM],
        /// Pose bits `[qw, qx, qy, qz, tx, ty, tz]`, or the error's Debug text.
        pose: Result<[u32; POSE_DIM], String>,
    },
    /// Inference failed: whether encoding alone succeeded, and the error's Debug text.
    Err {
        /// `encode_tiled` succeeded.
        encoded: bool,
        /// `Debug` of the error.
        error: String,
    },
}

/// Random int8 model through `pcrnet-core`'s seeded generator (identity
/// frame, sources not centred).
pub fn random_model(name: &str, seed: u64, encoder: &[u16], head: &[u16]) -> TestModel {
    random_model_with(name, seed, encoder, head, false, Frame::IDENTITY)
}

/// As [`random_model`], choosing whether the model centres sources and its
/// frame (user units -> model frame).
pub fn random_model_with(
    name: &str,
    seed: u64,
    encoder: &[u16],
    head: &[u16],
    centre_source: bool,
    frame: Frame,
) -> TestModel {
    let (mut arena, mut out) = (vec![0u8; 8 << 20], vec![0u8; 8 << 20]);
    let blob = random_int8_blob_with(
        seed,
        encoder,
        head,
        centre_source,
        frame,
        &mut arena,
        &mut out,
    )
    .expect("random model parameters are valid")
    .to_vec();
    TestModel {
        name: name.into(),
        blob,
    }
}

/// The int8 model `blob` with a random PointNetLK solver (`pcrnet-core`'s
/// seeded [`with_random_lk_solver`]), without its head if `headless`.
pub fn with_lk_solver(blob: &[u8], name: &str, seed: u64, headless: bool) -> TestModel {
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; blob.len() + (1 << 20)]);
    let blob = with_random_lk_solver(blob, seed, headless, &mut arena, &mut out)
        .expect("test models take a solver")
        .to_vec();
    TestModel {
        name: name.into(),
        blob,
    }
}

fn uniform(rng: &mut SplitMix64, n: usize, extent: f32) -> Vec<[f32; 3]> {
    (0..n)
        .map(|_| [0; 3].map(|_: i32| rng.uniform(-extent, extent)))
        .collect()
}

/// Clouds for one model: sizes from 1 to `max_points`, extreme coordinates
/// at the edge of the input range, tiny and signed-zero values, a line
/// (degenerate for registration), and invalid clouds (empty, NaN,
/// infinity, out of range).
///
/// They are made in model units; for a model with a non-identity frame
/// (the exporter's frames never are exactly the identity) every point is
/// then moved to user units (`p / scale + centre`), the units the model's
/// callers use, edge-of-range and out-of-range points included.
pub fn clouds_for(model: &[u8], seed: u64, sizes: &[usize]) -> Vec<(String, Vec<[f32; 3]>)> {
    let frame = *Int8Model::from_bytes(model)
        .expect("test models are valid")
        .frame();
    let mut clouds = clouds_in_model_units(model, seed, sizes);
    if frame != Frame::IDENTITY {
        for p in clouds.iter_mut().flat_map(|(_, c)| c.iter_mut()) {
            *p = [0, 1, 2].map(|k| p[k] / frame.scale + frame.centre[k]);
        }
    }
    clouds
}

fn clouds_in_model_units(model: &[u8], seed: u64, sizes: &[usize]) -> Vec<(String, Vec<[f32; 3]>)> {
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    let edge = 32767.0 * m.payload().input_scale;
    let mut rng = SplitMix64(seed);
    let mut out = Vec::new();
    for &n in sizes {
        out.push((format!("uniform {n}"), uniform(&mut rng, n, 1.0)));
    }
    // Largest representable coordinates, on every axis and sign.
    let mut extreme = uniform(&mut rng, 40, edge);
    for (i, p) in extreme.iter_mut().enumerate().take(24) {
        let axis = i % 3;
        p[axis] = if i % 2 == 0 { edge } else { -edge };
        if i >= 12 {
            *p = [edge * (1.0 - f32::EPSILON); 3];
        }
    }
    out.push(("extreme coordinates".into(), extreme));
    out.push((
        "tiny and signed zeros".into(),
        vec![
            [0.0, -0.0, 0.0],
            [1e-30, -1e-38, f32::MIN_POSITIVE / 2.0],
            [-0.0, -0.0, -0.0],
            [
                m.payload().input_scale / 2.0,
                -m.payload().input_scale / 2.0,
                0.0,
            ],
        ],
    ));
    let line: Vec<[f32; 3]> = (0..30)
        .map(|_| {
            let t = rng.uniform(-1.0, 1.0);
            [0.3 * t, -0.2 * t, 0.5 * t]
        })
        .collect();
    out.push(("points on a line".into(), line));
    out.push(("empty".into(), Vec::new()));
    let mut nan = uniform(&mut rng, 12, 1.0);
    nan[5][1] = f32::NAN;
    out.push(("NaN at point 5".into(), nan));
    let mut inf = uniform(&mut rng, 12, 1.0);
    inf[11][2] = f32::NEG_INFINITY;
    out.push(("-inf at point 11".into(), inf));
    let mut far = uniform(&mut rng, 12, 1.0);
    far[3][0] = edge * 1.001;
    out.push(("out of range at point 3".into(), far));
    out
}

/// What the host's `pcrnet-core` computes for a case (the same calls the device makes).
pub fn expected(model: &[u8], case: &Case) -> Expected {
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    // Room for any tile and for the host's block kernel (x86-64), so
    // the device is compared with the host's fastest path.
    let mut scratch = vec![0i8; m.host_scratch_len()];
    let encoded = m.encode_tiled(&case.cloud, case.tile, &mut scratch).is_ok();
    match m.infer_tiled(&case.cloud, case.tile, &mut scratch) {
        Ok(r) => Expected::Ok {
            feature: r.feature.to_vec(),
            head: r.head,
            pose: m
                .pose(&r.head)
                .map(|p| pose_bits(&p))
                .map_err(|e| error_text(&e)),
        },
        Err(e) => Expected::Err {
            encoded,
            error: error_text(&e),
        },
    }
}

fn push_u32(buf: &mut Vec<u8>, v: usize) {
    buf.extend_from_slice(&u32::try_from(v).expect("fits the container").to_le_bytes());
}

fn align4(buf: &mut Vec<u8>) {
    while !buf.len().is_multiple_of(4) {
        buf.push(0);
    }
}

/// An option set as the container's words: `passes tolerance hypotheses
/// screen_iterations icp_iterations metric icp_tolerance icp_distance
/// inlier_distance max_points max_residual lk_iterations network_points` (counts as u32, f32 as their
/// bits, metric 0 point-to-point / 1 point-to-plane). Every field: a field added to `Options` fails to compile here.
pub fn options_words(o: &Options) -> anyhow::Result<[u32; OPTIONS_WORDS]> {
    let Options {
        passes,
        tolerance,
        hypotheses,
        screen_iterations,
        icp_iterations,
        metric,
        icp_tolerance,
        icp_distance,
        inlier_distance,
        max_points,
        max_residual,
        lk_iterations,
        network_points,
    } = *o;
    Ok([
        u32::try_from(passes)?,
        tolerance.to_bits(),
        u32::try_from(hypotheses)?,
        u32::try_from(screen_iterations)?,
        u32::try_from(icp_iterations)?,
        match metric {
            Metric::PointToPoint => 0,
            Metric::PointToPlane => 1,
        },
        icp_tolerance.to_bits(),
        icp_distance.to_bits(),
        inlier_distance.to_bits(),
        u32::try_from(max_points)?,
        max_residual.to_bits(),
        u32::try_from(lk_iterations)?,
        u32::try_from(network_points)?,
    ])
}

/// What the device makes of [`options_words`] (the same code as the runner's).
pub fn options_from_words(w: &[u32; OPTIONS_WORDS]) -> Options {
    Options {
        passes: w[0] as usize,
        tolerance: f32::from_bits(w[1]),
        hypotheses: w[2] as usize,
        screen_iterations: w[3] as usize,
        icp_iterations: w[4] as usize,
        metric: if w[5] == 0 {
            Metric::PointToPoint
        } else {
            Metric::PointToPlane
        },
        icp_tolerance: f32::from_bits(w[6]),
        icp_distance: f32::from_bits(w[7]),
        inlier_distance: f32::from_bits(w[8]),
        max_points: w[9] as usize,
        max_residual: f32::from_bits(w[10]),
        lk_iterations: w[11] as usize,
        network_points: w[12] as usize,
    }
}

fn push_options(buf: &mut Vec<u8>, o: &Options) -> anyhow::Result<()> {
    for w in options_words(o)? {
        buf.extend_from_slice(&w.to_le_bytes());
    }
    Ok(())
}

/// Lays out the container the device runner reads (see `tests/firmware`),
/// failing if it takes more than `capacity` bytes (the board's data region).
pub fn container(models: &[TestModel], cases: &[Case], capacity: usize) -> anyhow::Result<Vec<u8>> {
    let header = 16 + 8 * models.len() + 4 * CASE_WORDS * cases.len();
    let mut data = vec![0u8; header];
    let mut table = Vec::with_capacity(header);
    table.extend_from_slice(b"PCRV");
    push_u32(&mut table, CONTAINER_VERSION as usize);
    push_u32(&mut table, models.len());
    push_u32(&mut table, cases.len());
    for m in models {
        align4(&mut data);
        push_u32(&mut table, data.len());
        push_u32(&mut table, m.blob.len());
        data.extend_from_slice(&m.blob);
    }
    for c in cases {
        align4(&mut data);
        push_u32(&mut table, c.model);
        push_u32(&mut table, data.len());
        push_u32(&mut table, c.cloud.len());
        push_u32(&mut table, c.tile);
        push_u32(&mut table, c.iterations);
        for v in c.cloud.iter().flatten() {
            data.extend_from_slice(&v.to_le_bytes());
        }
        push_u32(&mut table, c.registrations.len());
        push_u32(&mut table, data.len());
        for o in &c.registrations {
            push_options(&mut data, o)?;
        }
    }
    debug_assert_eq!(table.len(), header);
    data[..header].copy_from_slice(&table);
    anyhow::ensure!(
        data.len() <= capacity,
        "test vectors take {} bytes, the board's data region has {capacity}",
        data.len()
    );
    Ok(data)
}

/// A cloud stored as x, y, z f32 little-endian per point (as
/// `models/embedded-default-source.f32`, the shipped model's demo source).
pub fn read_cloud(path: &std::path::Path) -> anyhow::Result<Vec<[f32; 3]>> {
    use anyhow::Context;
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    anyhow::ensure!(
        !bytes.is_empty() && bytes.len().is_multiple_of(12),
        "{}: {} bytes is not a whole number of f32 x y z points",
        path.display(),
        bytes.len()
    );
    Ok(bytes
        .chunks_exact(12)
        .map(|p| {
            [0, 1, 2]
                .map(|k| f32::from_le_bytes([p[4 * k], p[4 * k + 1], p[4 * k + 2], p[4 * k + 3]]))
        })
        .collect())
}

/// The cloud twice, the second copy [`jittered`]: a denser scan of the
/// same surface.
pub fn doubled(cloud: &[[f32; 3]], seed: u64, jitter: f32) -> Vec<[f32; 3]> {
    let second = jittered(cloud, seed, jitter);
    cloud.iter().copied().chain(second).collect()
}

/// The cloud with every coordinate moved by a seeded jitter in
/// `[-jitter, jitter)` (uniform: standard deviation `jitter / sqrt(3)`).
pub fn jittered(cloud: &[[f32; 3]], seed: u64, jitter: f32) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    cloud
        .iter()
        .map(|p| p.map(|x| x + rng.uniform(-jitter, jitter)))
        .collect()
}
