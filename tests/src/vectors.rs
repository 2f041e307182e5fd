//! Test models, clouds and the container the device reads.

use pcrnet_core::testing::{SplitMix64, random_int8_blob_into};
use pcrnet_core::{Int8Model, MAX_TILE, POSE_DIM};

/// Where the container goes in the MPS2 PSRAM.
pub const PSRAM_BASE: u32 = 0x2100_0000;
/// PSRAM size.
pub const PSRAM_LEN: usize = 16 << 20;

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
    let mut scratch = vec![0i8; m.scratch_len(MAX_TILE)];
    Some(
        m.network_pose(&case.cloud, case.iterations, 0.0, &mut scratch)
            .map(|(p, n)| (n, pose_bits(&p)))
            .map_err(|e| format!("{e:?}")),
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

/// Random int8 model through `pcrnet-core`'s seeded generator.
pub fn random_model(name: &str, seed: u64, encoder: &[u16], head: &[u16]) -> TestModel {
    let (mut arena, mut out) = (vec![0u8; 8 << 20], vec![0u8; 8 << 20]);
    let blob = random_int8_blob_into(seed, encoder, head, &mut arena, &mut out)
        .expect("random model parameters are valid")
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
/// at the edge of the input range, tiny and signed-zero values, and invalid
/// clouds (empty, NaN, infinity, out of range).
pub fn clouds_for(model: &[u8], seed: u64, sizes: &[usize]) -> Vec<(String, Vec<[f32; 3]>)> {
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
    let mut scratch = vec![0i8; 64 * 1024];
    let encoded = m.encode_tiled(&case.cloud, case.tile, &mut scratch).is_ok();
    match m.infer_tiled(&case.cloud, case.tile, &mut scratch) {
        Ok(r) => Expected::Ok {
            feature: r.feature.to_vec(),
            head: r.head,
            pose: m
                .pose(&r.head)
                .map(|p| pose_bits(&p))
                .map_err(|e| format!("{e:?}")),
        },
        Err(e) => Expected::Err {
            encoded,
            error: format!("{e:?}"),
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

/// Lays out the container the device runner reads (see `tests/firmware`).
pub fn container(models: &[TestModel], cases: &[Case]) -> anyhow::Result<Vec<u8>> {
    let header = 16 + 8 * models.len() + 20 * cases.len();
    let mut data = vec![0u8; header];
    let mut table = Vec::with_capacity(header);
    table.extend_from_slice(b"PCRV");
    push_u32(&mut table, 2);
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
    }
    data[..header].copy_from_slice(&table);
    anyhow::ensure!(
        data.len() <= PSRAM_LEN,
        "test vectors take {} bytes, PSRAM has {PSRAM_LEN}",
        data.len()
    );
    Ok(data)
}
