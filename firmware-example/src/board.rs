//! The emulated board: QEMU's machines differ in their memory map, in
//! where a large block of data can be loaded (the QEMU harness's test
//! vectors) and in how instructions are counted. One cargo feature per
//! board that shares its Rust target with another; the map of code and
//! SRAM comes from a `memory-*.x` file chosen by `build.rs`.
//!
//! | board (feature) | core | Rust target | code / SRAM | data region | counter |
//! |---|---|---|---|---|---|
//! | `mps2-an386` (default) | Cortex-M4F | `thumbv7em-none-eabihf` | 0x0 / 0x2000_0000 | PSRAM 0x2100_0000, 16 MiB | SysTick 25 MHz |
//! | `mps2-an385` (default) | Cortex-M3 | `thumbv7m-none-eabi` | 0x0 / 0x2000_0000 | PSRAM 0x2100_0000, 16 MiB | SysTick 25 MHz |
//! | `mps2-an500` | Cortex-M7 | `thumbv7em-none-eabihf` | 0x0 / 0x2000_0000 | PSRAM 0x6000_0000, 16 MiB | SysTick 25 MHz |
//! | `mps2-an505` | Cortex-M33 | `thumbv8m.main-none-eabihf` | 0x1000_0000 / 0x3800_0000 (secure) | PSRAM 0x8000_0000, 16 MiB | SysTick 20 MHz |
//! | `microbit` | Cortex-M0 (nRF51) | `thumbv6m-none-eabi` | 0x0, 128 KiB / 0x2000_0000, 16 KiB | flash 0x2_0000, 128 KiB | SysTick 16 MHz |
//! | `virt` (riscv32 targets) | RISC-V rv32imac | `riscv32imac-unknown-none-elf` | 0x8000_0000 / 0x8040_0000 (both RAM) | RAM 0x8100_0000, 16 MiB | `minstret` |
//!
//! Addresses from QEMU's `info mtree -f` of each machine; clocks from
//! QEMU's board models, checked on every run by the QEMU harness's
//! instruction-counter calibration.

#[cfg(all(
    target_arch = "arm",
    not(any(feature = "mps2-an500", feature = "mps2-an505", feature = "microbit"))
))]
mod values {
    pub const RAM_BASE: usize = 0x2000_0000;
    pub const DATA_BASE: usize = 0x2100_0000;
    pub const DATA_LEN: usize = 16 << 20;
    pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 40_000;
}

#[cfg(feature = "mps2-an500")]
mod values {
    pub const RAM_BASE: usize = 0x2000_0000;
    pub const DATA_BASE: usize = 0x6000_0000;
    pub const DATA_LEN: usize = 16 << 20;
    pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 40_000;
}

#[cfg(feature = "mps2-an505")]
mod values {
    pub const RAM_BASE: usize = 0x3800_0000;
    pub const DATA_BASE: usize = 0x8000_0000;
    pub const DATA_LEN: usize = 16 << 20;
    pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 50_000;
}

#[cfg(feature = "microbit")]
mod values {
    pub const RAM_BASE: usize = 0x2000_0000;
    pub const DATA_BASE: usize = 0x0002_0000;
    pub const DATA_LEN: usize = 128 << 10;
    pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 62_500;
}

#[cfg(target_arch = "riscv32")]
mod values {
    pub const RAM_BASE: usize = 0x8040_0000;
    pub const DATA_BASE: usize = 0x8100_0000;
    pub const DATA_LEN: usize = 16 << 20;
    pub const INSTRUCTIONS_PER_1000_TICKS: u64 = 1_000;
}

/// Start of SRAM (where `.data` and `.bss` begin).
pub const RAM_BASE: usize = values::RAM_BASE;
/// Base address of the data region (see the table).
pub const DATA_BASE: usize = values::DATA_BASE;
/// Size of the data region.
pub const DATA_LEN: usize = values::DATA_LEN;
/// Instructions per 1,000 counter ticks. QEMU run with `-icount shift=0`
/// advances virtual time 1 ns per instruction, so SysTick on a 25 MHz
/// clock ticks every 40 instructions; RISC-V's `minstret` counts
/// instructions themselves.
pub const INSTRUCTIONS_PER_1000_TICKS: u64 = values::INSTRUCTIONS_PER_1000_TICKS;

#[cfg(any(
    all(feature = "mps2-an500", feature = "mps2-an505"),
    all(feature = "mps2-an500", feature = "microbit"),
    all(feature = "mps2-an505", feature = "microbit"),
))]
compile_error!("choose one board feature");

/// Prints one line to the host (semihosting).
pub fn print(line: &str) {
    #[cfg(target_arch = "arm")]
    cortex_m_semihosting::hprintln!("{}", line);
    #[cfg(target_arch = "riscv32")]
    semihosting::println!("{}", line);
}

/// Ends the program (semihosting exit: QEMU exits with 0 or 1).
pub fn exit(success: bool) -> ! {
    #[cfg(target_arch = "arm")]
    {
        use cortex_m_semihosting::debug;
        debug::exit(if success {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        loop {
            cortex_m::asm::wfi();
        }
    }
    #[cfg(target_arch = "riscv32")]
    semihosting::process::exit(if success { 0 } else { 1 })
}

/// The current stack pointer.
#[inline(always)]
pub fn stack_pointer() -> usize {
    #[cfg(target_arch = "arm")]
    {
        cortex_m::register::msp::read() as usize
    }
    #[cfg(target_arch = "riscv32")]
    {
        let sp: usize;
        // SAFETY: reads a register, touches nothing.
        unsafe { core::arch::asm!("mv {}, sp", out(reg) sp) };
        sp
    }
}
