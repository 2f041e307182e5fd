//! pcrnet firmware example: register a stored point cloud against the
//! model's template, with the int8 model used in place from flash and all
//! working memory in statics. Prints the pose, its residual and whether it
//! is reliable, and the instruction count over semihosting.
//!
//! It acts on the confidence: a pose that is not reliable is retried with
//! every flip hypothesis the blob stores; if that is still not reliable, the
//! example reports that it has no pose to act on (a real application would
//! keep its last good pose or ask for another view).
//!
//! Memory (embedded default architecture, tile 8): model blob in flash
//! (~230 KB), scratch 4,355 B and the cloud 12 B/point in RAM; stack and
//! totals are measured by `cargo xtask size` / `cargo xtask qemu-test`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
#[cfg(feature = "defmt")]
use defmt_semihosting as _;
use panic_semihosting as _;
use pcrnet_core::{Int8Model, MAX_TILE, Options, Registration, int8_scratch_len};
use pcrnet_firmware_example::{icount::Counter, stack};

/// Text over semihosting, or defmt frames with the `defmt` feature.
#[cfg(not(feature = "defmt"))]
macro_rules! log {
    ($($t:tt)*) => { cortex_m_semihosting::hprintln!($($t)*) };
}
#[cfg(feature = "defmt")]
macro_rules! log {
    ($($t:tt)*) => { defmt::println!($($t)*) };
}

/// The int8 model, used in place from flash (no alignment needed).
static MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
/// A stored source cloud: x, y, z as f32 little-endian per point. On a real
/// device a sensor driver fills the cloud buffer instead.
const SOURCE: &[u8] = include_bytes!("../../models/embedded-default-source.f32");
const POINTS: usize = SOURCE.len() / 12;
/// Scratch for the model's architecture at the largest tile; `Int8Model::load`
/// checks it is big enough.
const SCRATCH: usize = int8_scratch_len(&[32, 64, 128, 256], &[256, 128, 64], MAX_TILE);

#[entry]
fn main() -> ! {
    // cortex-m-rt makes these `&'static mut`: RAM owned by `main`, no heap.
    static mut SCRATCH_BUF: [i8; SCRATCH] = [0; SCRATCH];
    static mut CLOUD: [[f32; 3]; POINTS] = [[0.0; 3]; POINTS];

    stack::paint();
    let Some(core) = cortex_m::Peripherals::take() else {
        log!("core peripherals already taken");
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    };
    let counter = Counter::start(core.SYST);

    for (p, bytes) in CLOUD.iter_mut().zip(SOURCE.chunks_exact(12)) {
        for (x, b) in p.iter_mut().zip(bytes.chunks_exact(4)) {
            *x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
    }

    // Stack of each phase, measured by painting (see `stack`).
    let baseline = stack::paint();
    let loaded = Int8Model::load(MODEL, SCRATCH_BUF);
    let load_stack = stack::used_below(baseline);
    let code = match loaded {
        Ok(model) => {
            log!("points: {}", POINTS);
            // The recommended pipeline: one network pass, 4 starting poses,
            // ICP against the template's points, residual.
            let options = Options::default();
            let baseline = stack::paint();
            let start = counter.instructions();
            let mut result = model.register(CLOUD, &options, SCRATCH_BUF);
            log!("instructions: {}", counter.instructions() - start);
            let register_stack = stack::used_below(baseline);
            if let Ok(r) = &result {
                report(r);
                if !r.reliable {
                    // Act on the confidence: try every stored turn before giving up.
                    let all = Options {
                        hypotheses: usize::MAX,
                        ..options
                    };
                    log!("not reliable: retrying with every flip hypothesis");
                    let start = counter.instructions();
                    result = model.register(CLOUD, &all, SCRATCH_BUF);
                    log!("instructions: {}", counter.instructions() - start);
                    if let Ok(r) = &result {
                        report(r);
                    }
                }
            }
            log!(
                "stack: load {} B, register {} B, below main's {} B",
                load_stack,
                register_stack,
                stack::in_use(baseline)
            );
            match result {
                Ok(r) if r.reliable => {
                    log!("pose reliable: acting on it");
                    debug::EXIT_SUCCESS
                }
                Ok(_) => {
                    log!("no reliable pose: keeping the last good one");
                    debug::EXIT_SUCCESS
                }
                Err(e) => {
                    log!("registration failed: {:?}", e);
                    debug::EXIT_FAILURE
                }
            }
        }
        Err(e) => {
            log!("model rejected: {:?}", e);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(code);
    // Not reached under QEMU (semihosting exit ends the emulator).
    loop {
        cortex_m::asm::wfi();
    }
}

/// Prints a registration's pose and confidence.
fn report(r: &Registration) {
    log!("rotation (w, x, y, z): {:?}", r.pose.rotation);
    log!("translation: {:?}", r.pose.translation);
    log!(
        "residual: {:?}, plane residual {:?} ({:?} of the template's size), fitness {:?}, hypothesis {}, ICP iterations {}, saturated {}",
        r.residual,
        r.plane_residual,
        r.relative_plane_residual,
        r.fitness,
        r.hypothesis,
        r.icp_iterations,
        r.saturated
    );
    log!("reliable: {}", r.reliable);
}
