//! What the fuzz targets share: running a loaded model on a cloud with
//! every result checked, sealing payload bytes into a blob, and turning
//! bytes into clouds.
//!
//! A target fails (libFuzzer reports a crash) on a panic, on an allocation
//! failure, or on an `Ok` result holding a non-finite value.

use pcrnet_core::format::{CRC_LEN, FORMAT_VERSION, HEADER_LEN, MAGIC, ModelKind, OLDEST_READABLE};
use pcrnet_core::{F32Model, Int8Model, Metric, Options, Registration};

/// Fewer ICP iterations than the default: the same code (screening one
/// iteration past `refine::SCREEN_CHECK`, so its check and resumed ICP
/// run), faster runs.
pub fn quick_options() -> Options {
    Options {
        icp_iterations: 6,
        screen_iterations: 4,
        ..Options::default()
    }
}

/// Options read from 16 bytes (any value, valid or not).
pub fn options_from(bytes: &[u8; 16]) -> Options {
    let f = |i: usize| f32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    Options {
        passes: 1 + (bytes[0] % 3) as usize,
        tolerance: f(1).abs(),
        hypotheses: bytes[5] as usize,
        // Past `refine::SCREEN_CHECK`, so that screening's check and its
        // resumed ICP are reached.
        screen_iterations: (bytes[6] % 8) as usize,
        icp_iterations: (bytes[7] % 12) as usize,
        metric: if bytes[8] & 1 == 0 {
            Metric::PointToPoint
        } else {
            Metric::PointToPlane
        },
        icp_tolerance: f(9),
        max_points: bytes[13] as usize * 4,
        // LK steps: `NoLkSolver` on a blob without PointNetLK's solver.
        lk_iterations: (bytes[14] % 3) as usize,
        network_points: bytes[15] as usize * 4,
        ..Options::default()
    }
}

/// `x y z` f32 triples from the bytes (the rest ignored), at most `max`.
pub fn cloud_from(bytes: &[u8], max: usize) -> Vec<[f32; 3]> {
    bytes
        .chunks_exact(12)
        .take(max)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect()
}

/// Panics (a finding) if an `Ok` registration holds a non-finite value.
pub fn check(r: &Registration) {
    let values = [
        r.residual,
        r.relative_residual,
        r.fitness,
        r.inlier_rmse,
        r.plane_residual,
        r.relative_plane_residual,
    ];
    assert!(
        r.pose.is_finite() && values.iter().all(|v| v.is_finite()),
        "non-finite result: {r:?}"
    );
}

/// A fixed 24-point source: two rings, not degenerate.
pub fn fixed_cloud() -> Vec<[f32; 3]> {
    (0..24)
        .map(|i| {
            let a = i as f32 * 0.5;
            [
                0.3 * a.cos(),
                0.2 * a.sin(),
                if i % 2 == 0 { 0.1 } else { -0.1 },
            ]
        })
        .collect()
}

/// Loads `blob` as int8 and as f32 and, where it loads, runs every entry
/// point on `cloud`.
pub fn run_blob(blob: &[u8], cloud: &[[f32; 3]], options: &Options) {
    if let Ok(m) = Int8Model::from_bytes(blob) {
        let mut scratch = vec![0i8; m.scratch_len(8).min(1 << 20)];
        if let Ok(r) = m.register(cloud, options, &mut scratch) {
            check(&r);
        }
        if let Ok((p, _)) = m.network_pose(cloud, 2, 0.0, &mut scratch) {
            assert!(p.is_finite());
        }
        let _ = m.infer_tiled(cloud, 3, &mut scratch);
        let mut small = [0i8; 64];
        let _ = Int8Model::load(blob, &small);
        let _ = m.encode(cloud, &mut small);
    }
    if let Ok(m) = F32Model::from_bytes(blob) {
        let mut scratch = vec![0f32; m.scratch_len().min(1 << 20)];
        if let Ok(r) = m.register(cloud, options, &mut scratch) {
            check(&r);
        }
        if let Ok(raw) = m.network().infer(cloud, &mut scratch) {
            assert!(raw.iter().all(|v| v.is_finite()));
        }
    }
}

/// A blob around arbitrary payload bytes: header (magic, format
/// `version`, `kind`, length) and a correct CRC, so the payload reaches the
/// decoder and the validation behind it (each readable version decodes
/// its own trailer).
pub fn seal(kind: ModelKind, version: u16, payload: &[u8]) -> Vec<u8> {
    const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len() + CRC_LEN);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&version.to_le_bytes());
    out.push(kind as u8);
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(payload);
    let crc = CRC32.checksum(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// The shipped embedded default (int8), for the targets that vary the cloud.
pub const SHIPPED: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");

/// The readable format version a fuzzer's byte picks: the current one for
/// 0, then older ones down to [`OLDEST_READABLE`], cycling.
pub fn version_of(byte: u8) -> u16 {
    let readable = FORMAT_VERSION - OLDEST_READABLE + 1;
    FORMAT_VERSION - u16::from(byte) % readable
}
