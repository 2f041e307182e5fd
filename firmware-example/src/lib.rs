//! Board support for the pcrnet firmware example on QEMU's MPS2 machines
//! (Cortex-M4F `mps2-an386` by default; M3, M7 and M33 boards in
//! [`board`]): the board's memory map, an instruction counter and stack
//! measurement. The application itself is `src/main.rs`.
#![no_std]

pub mod board;
pub mod icount;
pub mod stack;
