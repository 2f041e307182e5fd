//! Registrations for counting instructions on the host (under valgrind's
//! callgrind or `perf stat`): the shipped embedded default (int8) on the
//! shipped 512-point source, `N` times, with `K` hypotheses and `I` ICP
//! iterations (`Options::default()` otherwise; `K = 1, I = 0` is the
//! network and its score alone, to subtract). Prints the last pose, so
//! that the work is used. Counts on x86-64 are not the M4's
//! (`cargo xtask firmware-run` is), but a change to the search moves both.
//!
//! usage: `register_count K I N`

use std::process::ExitCode;

use pcrnet_core::{Int8Model, Options};

const USAGE: &str = "usage: register_count K I N";
const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
const SOURCE: &[u8] = include_bytes!("../../models/embedded-default-source.f32");

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("register_count: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().map_err(|_| USAGE.to_string()))
        .collect::<Result<_, _>>()?;
    let [hypotheses, icp_iterations, times] = args.as_slice() else {
        return Err(USAGE.into());
    };
    let source: Vec<[f32; 3]> = SOURCE
        .chunks_exact(12)
        .map(|p| [0, 4, 8].map(|o| f32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]])))
        .collect();
    let model = Int8Model::from_bytes(MODEL).map_err(|e| format!("model: {e}"))?;
    // The tile kernel, as on a device.
    let mut scratch = vec![0i8; model.scratch_len(1)];
    let options = Options {
        hypotheses: *hypotheses,
        icp_iterations: *icp_iterations,
        ..Options::default()
    };
    let mut last = None;
    for _ in 0..*times {
        last = Some(
            model
                .register(&source, &options, &mut scratch)
                .map_err(|e| format!("register: {e}"))?,
        );
    }
    if let Some(r) = last {
        println!("{:?} {:?} {}", r.pose, r.hypothesis, r.reliable);
    }
    Ok(())
}
