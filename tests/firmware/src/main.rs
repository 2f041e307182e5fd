//! Device side of the QEMU harness.
//!
//! QEMU's generic loader puts a test-vector container at the start of the
//! MPS2 PSRAM (0x2100_0000, 16 MiB; big enough for the paper-size model).
//! For every model in it, this program parses the model in place, then for
//! every case of that model measures the encoder alone and the whole
//! inference with the SysTick instruction counter, and prints the outputs as
//! text over semihosting. The host compares them with its own, bit for bit.
//!
//! Container (all u32 little-endian, offsets from its start, 4-aligned):
//! `b"PCRV" version n_models n_cases`, then `n_models x (offset, len)`,
//! then `n_cases x (model, cloud_offset, n_points, tile)`.
#![no_std]
#![no_main]

use core::fmt::Write;

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use heapless::String;
use panic_semihosting as _;
use pcrnet_core::Int8Model;
use pcrnet_firmware_example::{icount::Counter, stack};

const BASE: usize = 0x2100_0000;
const PSRAM_LEN: usize = 16 << 20;
const SCRATCH: usize = 64 * 1024;

fn word(index: usize) -> u32 {
    // SAFETY: PSRAM is always mapped on mps2-an386; reads stay inside it.
    unsafe { core::ptr::read_volatile((BASE + 4 * index.min(PSRAM_LEN / 4 - 1)) as *const u32) }
}

fn bytes(offset: u32, len: u32) -> &'static [u8] {
    let (o, l) = (offset as usize, len as usize);
    let l = l.min(PSRAM_LEN.saturating_sub(o));
    // SAFETY: inside PSRAM, which nothing else writes while we run.
    unsafe { core::slice::from_raw_parts((BASE + o.min(PSRAM_LEN)) as *const u8, l) }
}

fn points(offset: u32, n: u32) -> &'static [[f32; 3]] {
    let (o, n) = (offset as usize, n as usize);
    let n = n.min(PSRAM_LEN.saturating_sub(o) / 12);
    // SAFETY: the host aligns clouds to 4 bytes inside PSRAM; [f32; 3] has
    // alignment 4 and every bit pattern is a valid f32.
    unsafe { core::slice::from_raw_parts((BASE + o.min(PSRAM_LEN)) as *const [f32; 3], n) }
}

/// Prints one line (semihosting is slow per call: build the line first).
fn emit(line: &str) {
    hprintln!("{}", line);
}

#[entry]
fn main() -> ! {
    static mut SCRATCH_BUF: [i8; SCRATCH] = [0; SCRATCH];
    let core = cortex_m::Peripherals::take().unwrap();
    let counter = Counter::start(core.SYST);

    // Calibration: 2 instructions per iteration, 1,000,000 iterations.
    let t0 = counter.instructions();
    let mut n: u32 = 1_000_000;
    // SAFETY: a register-only countdown loop.
    unsafe { core::arch::asm!("2:", "subs {0}, #1", "bne 2b", inout(reg) n) };
    let t1 = counter.instructions();
    hprintln!("calibration {} {}", 2 * 1_000_000u64, t1 - t0);
    let _ = n;

    if &word(0).to_le_bytes() != b"PCRV" || word(1) != 2 {
        hprintln!("error no test vectors at {:#x}", BASE);
        debug::exit(debug::EXIT_FAILURE);
    }
    let (n_models, n_cases) = (word(2) as usize, word(3) as usize);
    hprintln!("static_ram {}", stack::static_ram());
    let cases = 4 + 2 * n_models;
    let mut line: String<8192> = String::new();
    for m in 0..n_models {
        let blob = bytes(word(4 + 2 * m), word(5 + 2 * m));
        let model = match Int8Model::from_bytes(blob) {
            Ok(model) => model,
            Err(e) => {
                hprintln!("model {} error {:?}", m, e);
                continue;
            }
        };
        for c in (0..n_cases).filter(|&c| word(cases + 5 * c) as usize == m) {
            let (cloud, tile) = (
                points(word(cases + 5 * c + 1), word(cases + 5 * c + 2)),
                word(cases + 5 * c + 3) as usize,
            );
            let baseline = stack::paint();
            let e0 = counter.instructions();
            let encoded = model.encode_tiled(cloud, tile, SCRATCH_BUF).is_ok();
            let e1 = counter.instructions();
            let result = model.infer_tiled(cloud, tile, SCRATCH_BUF).map(|r| {
                let pose = model.pose(&r.head);
                (r, pose)
            });
            let e2 = counter.instructions();
            let peak = stack::used_below(baseline);
            line.clear();
            match result {
                Ok((r, pose)) => {
                    let _ = write!(line, "case {c} ok {} {} {peak} feature ", e1 - e0, e2 - e1);
                    for &v in r.feature {
                        let _ = write!(line, "{:02x}", v as u8);
                    }
                    let _ = write!(line, " head");
                    for v in r.head {
                        let _ = write!(line, " {v}");
                    }
                    match pose {
                        Ok(p) => {
                            let _ = write!(line, " pose");
                            for v in p.rotation.iter().chain(&p.translation) {
                                let _ = write!(line, " {:08x}", v.to_bits());
                            }
                        }
                        Err(e) => {
                            let _ = write!(line, " pose_error {e:?}");
                        }
                    }
                }
                Err(e) => {
                    let _ = write!(line, "case {c} error {encoded} {e:?}");
                }
            }
            emit(&line);
            let iterations = word(cases + 5 * c + 4) as usize;
            if iterations > 0 {
                line.clear();
                match model.network_pose(cloud, iterations, 0.0, SCRATCH_BUF) {
                    Ok((p, n)) => {
                        let _ = write!(line, "case {c} iter ok {n}");
                        for v in p.rotation.iter().chain(&p.translation) {
                            let _ = write!(line, " {:08x}", v.to_bits());
                        }
                    }
                    Err(e) => {
                        let _ = write!(line, "case {c} iter error {e:?}");
                    }
                }
                emit(&line);
            }
        }
    }
    hprintln!("done");
    debug::exit(debug::EXIT_SUCCESS);
    // Not reached under QEMU (semihosting exit ends the emulator).
    loop {
        cortex_m::asm::wfi();
    }
}
