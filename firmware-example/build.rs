//! Puts the board's `memory.x` where the runtime's `link.x` (cortex-m-rt,
//! riscv-rt) finds it.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR is set by cargo"));
    // QEMU virt runs from RAM at 0x8000_0000, the AN505 (Cortex-M33) boots
    // secure from 0x1000_0000, the micro:bit has 16 KiB of RAM; the other
    // MPS2 boards share one map. (No file is named memory.x: the linker
    // would find it in the package directory before OUT_DIR.)
    let riscv = env::var("CARGO_CFG_TARGET_ARCH").is_ok_and(|a| a == "riscv32");
    let memory: &[u8] = if riscv {
        include_bytes!("memory-riscv-virt.x")
    } else if env::var_os("CARGO_FEATURE_MPS2_AN505").is_some() {
        include_bytes!("memory-an505.x")
    } else if env::var_os("CARGO_FEATURE_MICROBIT").is_some() {
        include_bytes!("memory-microbit.x")
    } else {
        include_bytes!("memory-mps2.x")
    };
    fs::write(out.join("memory.x"), memory).expect("write memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory-mps2.x");
    println!("cargo:rerun-if-changed=memory-an505.x");
    println!("cargo:rerun-if-changed=memory-microbit.x");
    println!("cargo:rerun-if-changed=memory-riscv-virt.x");
    // defmt's linker script, only when the `defmt` feature is on.
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
