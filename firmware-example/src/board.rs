//! The emulated board: QEMU's machines differ in their memory map, in
//! where a large block of data can be loaded (the QEMU harness's test
//! vectors) and in how fast SysTick counts. One cargo feature per board
//! other than the default; the map of code and SRAM comes from
//! `memory-mps2.x`, `memory-an505.x` or `memory-microbit.x`, chosen by
//! `build.rs`.
//!
//! | board (feature) | core | Rust target | code / SRAM | data region | SysTick |
//! |---|---|---|---|---|---|
//! | `mps2-an386` (default) | Cortex-M4F | `thumbv7em-none-eabihf` | 0x0 / 0x2000_0000 | PSRAM 0x2100_0000, 16 MiB | 25 MHz |
//! | `mps2-an385` (default) | Cortex-M3 | `thumbv7m-none-eabi` | 0x0 / 0x2000_0000 | PSRAM 0x2100_0000, 16 MiB | 25 MHz |
//! | `mps2-an500` | Cortex-M7 | `thumbv7em-none-eabihf` | 0x0 / 0x2000_0000 | PSRAM 0x6000_0000, 16 MiB | 25 MHz |
//! | `mps2-an505` | Cortex-M33 | `thumbv8m.main-none-eabihf` | 0x1000_0000 / 0x3800_0000 (secure) | PSRAM 0x8000_0000, 16 MiB | 20 MHz |
//! | `microbit` | Cortex-M0 (nRF51) | `thumbv6m-none-eabi` | 0x0, 128 KiB / 0x2000_0000, 16 KiB | flash 0x2_0000, 128 KiB | 16 MHz |
//!
//! Addresses from QEMU's `info mtree -f` of each machine; clocks from
//! QEMU's board models, checked on every run by the QEMU harness's
//! instruction-counter calibration.

/// Base address of the data region (see the table).
#[cfg(not(any(feature = "mps2-an500", feature = "mps2-an505", feature = "microbit")))]
pub const DATA_BASE: usize = 0x2100_0000;
/// Base address of the data region (see the table).
#[cfg(feature = "mps2-an500")]
pub const DATA_BASE: usize = 0x6000_0000;
/// Base address of the data region (see the table).
#[cfg(feature = "mps2-an505")]
pub const DATA_BASE: usize = 0x8000_0000;
/// Base address of the data region (see the table).
#[cfg(feature = "microbit")]
pub const DATA_BASE: usize = 0x0002_0000;

/// Size of the data region.
#[cfg(not(feature = "microbit"))]
pub const DATA_LEN: usize = 16 << 20;
/// Size of the data region.
#[cfg(feature = "microbit")]
pub const DATA_LEN: usize = 128 << 10;

/// Instructions per 1,000 SysTick ticks: QEMU with `-icount shift=0`
/// advances virtual time 1 ns per instruction, and SysTick runs on the
/// board's clock (25 MHz: 40 instructions a tick).
#[cfg(not(any(feature = "mps2-an505", feature = "microbit")))]
pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 40_000;
/// Instructions per 1,000 SysTick ticks (20 MHz).
#[cfg(feature = "mps2-an505")]
pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 50_000;
/// Instructions per 1,000 SysTick ticks (16 MHz).
#[cfg(feature = "microbit")]
pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 62_500;

#[cfg(any(
    all(feature = "mps2-an500", feature = "mps2-an505"),
    all(feature = "mps2-an500", feature = "microbit"),
    all(feature = "mps2-an505", feature = "microbit"),
))]
compile_error!("choose one board feature");
