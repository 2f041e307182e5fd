//! The emulated board: QEMU's MPS2 machines differ in where their 16 MiB
//! PSRAM sits and how fast SysTick counts. One cargo feature per board
//! other than the default; the memory map of code and SRAM comes from
//! `memory-mps2.x` (or `memory-an505.x`), chosen by `build.rs`.
//!
//! | board (feature) | core | Rust target | code / SRAM | PSRAM | SysTick |
//! |---|---|---|---|---|---|
//! | `mps2-an386` (default) | Cortex-M4F | `thumbv7em-none-eabihf` | 0x0 / 0x2000_0000 | 0x2100_0000 | 25 MHz |
//! | `mps2-an385` (default) | Cortex-M3 | `thumbv7m-none-eabi` | 0x0 / 0x2000_0000 | 0x2100_0000 | 25 MHz |
//! | `mps2-an500` | Cortex-M7 | `thumbv7em-none-eabihf` | 0x0 / 0x2000_0000 | 0x6000_0000 | 25 MHz |
//! | `mps2-an505` | Cortex-M33 | `thumbv8m.main-none-eabihf` | 0x1000_0000 / 0x3800_0000 (secure) | 0x8000_0000 | 20 MHz |
//!
//! Addresses from QEMU's `info mtree` of each machine; clocks from QEMU's
//! board models (`hw/arm/mps2.c`, `hw/arm/mps2-tz.c`), checked on every
//! run by the QEMU harness's instruction-counter calibration.

/// Base address of the 16 MiB PSRAM.
#[cfg(not(any(feature = "mps2-an500", feature = "mps2-an505")))]
pub const PSRAM_BASE: usize = 0x2100_0000;
/// Base address of the 16 MiB PSRAM.
#[cfg(feature = "mps2-an500")]
pub const PSRAM_BASE: usize = 0x6000_0000;
/// Base address of the 16 MiB PSRAM.
#[cfg(feature = "mps2-an505")]
pub const PSRAM_BASE: usize = 0x8000_0000;

/// PSRAM size.
pub const PSRAM_LEN: usize = 16 << 20;

/// Instructions per SysTick tick: QEMU with `-icount shift=0` advances
/// virtual time 1 ns per instruction; SysTick runs on the board's clock.
#[cfg(not(feature = "mps2-an505"))]
pub const INSTRUCTIONS_PER_TICK: u64 = 40;
/// Instructions per SysTick tick (20 MHz clock, 1 ns per instruction).
#[cfg(feature = "mps2-an505")]
pub const INSTRUCTIONS_PER_TICK: u64 = 50;

#[cfg(all(feature = "mps2-an500", feature = "mps2-an505"))]
compile_error!("choose one board feature");
