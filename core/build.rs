//! Enables the Cortex-M4/M7 DSP kernels (SMLAD) on thumbv7em targets.
//! Rust exposes no `target_feature` cfg for the DSP extension, so the
//! target name decides; every other target uses the portable kernel.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(pcrnet_arm_dsp)");
    println!("cargo::rerun-if-changed=build.rs");
    let target = std::env::var("TARGET").unwrap_or_default();
    if target.starts_with("thumbv7em") {
        println!("cargo::rustc-cfg=pcrnet_arm_dsp");
    }
}
