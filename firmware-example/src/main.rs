//! pcrnet firmware example: register a stored point cloud against the
//! model's template, with the int8 model used in place from flash and all
//! working memory in statics. Prints the pose and the instruction count
//! over semihosting.
//!
//! Memory (embedded default architecture, tile 8): model blob in flash
//! (~224 KB), scratch 2,304 B and the cloud 12 B/point in RAM; stack and
//! totals are measured by `cargo xtask size` / `cargo xtask qemu-test`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
#[cfg(feature = "defmt")]
use defmt_semihosting as _;
use panic_semihosting as _;
use pcrnet_core::{Int8Model, MAX_TILE, int8_scratch_len};
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
    let core = cortex_m::Peripherals::take().unwrap();
    let counter = Counter::start(core.SYST);

    for (p, bytes) in CLOUD.iter_mut().zip(SOURCE.chunks_exact(12)) {
        for (x, b) in p.iter_mut().zip(bytes.chunks_exact(4)) {
            *x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
    }

    let code = match Int8Model::load(MODEL, SCRATCH_BUF) {
        Ok(model) => {
            let start = counter.instructions();
            let result = model.register(CLOUD, SCRATCH_BUF);
            let used = counter.instructions() - start;
            match result {
                Ok(pose) => {
                    log!("points: {}", POINTS);
                    log!("rotation (w, x, y, z): {:?}", pose.rotation);
                    log!("translation: {:?}", pose.translation);
                    log!("instructions: {}", used);
                    log!("peak stack: {} bytes", stack::peak());
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
