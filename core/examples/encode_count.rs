//! Encoder calls for counting instructions under an emulator (`cargo xtask
//! aarch64-count` runs it under qemu-aarch64): the encoder bench's cloud
//! (1,024 points, seed 1) through a random int8 model of the embedded
//! (`small`: 32-64-128-256) or the paper's widths (seed 2), on the tile
//! kernel (`tile`: scratch for tiles of `MAX_TILE` points) or the host
//! block kernel where the CPU has one (`host`: `host_scratch_len`), `N`
//! times. Prints the feature's first value, so that the work is used.
//!
//! usage: `encode_count small|paper tile|host N`

use std::process::ExitCode;

use pcrnet_core::arch::{PAPER_ENCODER, PCRNET_HEAD};
use pcrnet_core::testing::{SplitMix64, random_int8_blob_into};
use pcrnet_core::{Int8Model, MAX_TILE};

const USAGE: &str = "usage: encode_count small|paper tile|host N";

fn main() -> ExitCode {
    match run() {
        Ok(first) => {
            println!("{first}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("encode_count: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<i8, String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [widths, kernel, times] = args.as_slice() else {
        return Err(USAGE.into());
    };
    let (encoder, head): (&[u16], &[u16]) = match widths.as_str() {
        "small" => (&[32, 64, 128, 256], &[256, 128, 64]),
        "paper" => (PAPER_ENCODER, PCRNET_HEAD),
        _ => return Err(USAGE.into()),
    };
    let times: usize = times.parse().map_err(|_| USAGE.to_string())?;
    let mut rng = SplitMix64(1);
    let cloud: Vec<[f32; 3]> = (0..1024)
        .map(|_| [0; 3].map(|_: i32| rng.uniform(-1.0, 1.0)))
        .collect();
    let (mut arena, mut out) = (vec![0u8; 20 << 20], vec![0u8; 20 << 20]);
    let blob = random_int8_blob_into(2, encoder, head, &mut arena, &mut out)
        .map_err(|e| format!("random model: {e}"))?;
    let model = Int8Model::from_bytes(blob).map_err(|e| format!("model: {e}"))?;
    let mut scratch = vec![
        0i8;
        match kernel.as_str() {
            "tile" => model.scratch_len(MAX_TILE),
            "host" => model.host_scratch_len(),
            _ => return Err(USAGE.into()),
        }
    ];
    let mut first = 0;
    for _ in 0..times {
        let feature = model
            .encode(&cloud, &mut scratch)
            .map_err(|e| format!("encode: {e}"))?;
        first = feature.first().copied().unwrap_or(0);
    }
    Ok(first)
}
