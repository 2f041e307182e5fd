//! Board support for the pcrnet firmware example and the QEMU harness's
//! device runner, on QEMU's machines (Cortex-M4F `mps2-an386` by default;
//! the M3, M7, M33, M0 and RISC-V boards in [`board`]): the memory map,
//! semihosting output, an instruction counter and stack measurement. The
//! application itself (Cortex-M) is `src/main.rs`.
#![no_std]

pub mod board;
pub mod icount;
pub mod stack;
