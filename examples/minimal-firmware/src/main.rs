//! The smallest pcrnet firmware (Cortex-M4F; QEMU's mps2-an386 board):
//! use the int8 model blob in place from flash, register one point cloud
//! against the template stored in the blob, print the pose and whether to
//! trust it over semihosting, and exit. `cargo run --release` runs it.
//!
//! To start your own: copy this folder, point `MODEL` at your blob, make
//! `read_sensor` read your sensor, and change `memory.x` for your chip.
#![no_std] // No operating system: `core` only, no heap.
#![no_main] // cortex-m-rt's reset handler calls `main` (`#[entry]`).

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _; // A panic prints its message and exits.
use pcrnet_core::{Error, Int8Model, MAX_TILE, Options, scratch_len_for};

/// The model (`pcrnet export` writes it), used in place from flash: no
/// copy into RAM, no alignment needed.
const MODEL: &[u8] = include_bytes!("../../../models/embedded-default-int8.pcrn");

/// Bytes of working memory the model needs, read from the blob by the
/// compiler (for `MAX_TILE` points per encoder pass, the fastest). The
/// build stops here if `MODEL` is not an int8 pcrnet blob.
const SCRATCH: usize = scratch_len_for(MODEL, MAX_TILE).expect("not a pcrnet int8 blob");

// `SOURCE_POINTS`, a stored cloud (x, y, z in the template's units):
// build.rs writes it from an XYZ file.
include!(concat!(env!("OUT_DIR"), "/source.rs"));

/// The points to register: here the stored cloud; on a device, what the
/// sensor driver just measured (any number of points from 1).
fn read_sensor() -> &'static [[f32; 3]] {
    &SOURCE_POINTS
}

#[entry]
fn main() -> ! {
    // cortex-m-rt hands a `static mut` declared here to `main` as a
    // `&'static mut` (main runs once): the scratch sits in RAM, in .bss.
    static mut SCRATCH_BUF: [i8; SCRATCH] = [0; SCRATCH];

    let code = match register(SCRATCH_BUF) {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(e) => {
            hprintln!("error: {:?}", e);
            debug::EXIT_FAILURE
        }
    };
    // Ends QEMU (or the debug session) with that status.
    debug::exit(code);
    loop {
        cortex_m::asm::wfi(); // Not reached under QEMU: sleep.
    }
}

/// Loads the model and registers the sensor's points once.
fn register(scratch: &mut [i8]) -> Result<(), Error> {
    // Checks the blob (magic, version, CRC, every size) and the scratch.
    let model = Int8Model::load(MODEL, scratch)?;
    // The recommended pipeline: the network, flip resolution, ICP
    // against the template's points, the residual and its verdict.
    let r = model.register(read_sensor(), &Options::default(), scratch)?;
    // The pose moves the source onto the template: p' = R(rotation) p + t.
    hprintln!("rotation (w, x, y, z): {:?}", r.pose.rotation);
    hprintln!("translation: {:?}", r.pose.translation);
    hprintln!("residual: {:?}", r.residual);
    // Act on the pose only if reliable (a low residual, a source that is
    // not degenerate); otherwise keep the last good pose.
    hprintln!("reliable: {}", r.reliable);
    Ok(())
}
