//! Board support for the pcrnet firmware example on QEMU's `mps2-an386`
//! (Cortex-M4F): an instruction counter and stack measurement. The
//! application itself is `src/main.rs`.
#![no_std]

pub mod icount;
pub mod stack;
