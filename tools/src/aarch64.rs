//! The aarch64 commands: core's tests under qemu-aarch64, and instruction
//! counts of its encoder kernels there.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

use crate::{cargo, ensure_apt, ensure_targets, root, run_with_env};

/// The 64-bit Arm Linux target of both commands.
const AARCH64: &str = "aarch64-unknown-linux-gnu";

/// Clippy on pcrnet-core's aarch64 code, then its tests with `std` for
/// aarch64 Linux under qemu-aarch64 (user mode), once on QEMU's `max` CPU
/// (with `dotprod`: the `SDOT` tile, head and block kernels) and once on a
/// Cortex-A53 (without: the `SMULL` tile and head kernels, no block
/// kernel).
pub fn test() -> Result<(), String> {
    ensure_tools()?;
    let core = [
        "-p",
        "pcrnet-core",
        "--features",
        "std",
        "--target",
        AARCH64,
    ];
    cargo(
        &[
            &["clippy"][..],
            &core,
            &["--all-targets", "--", "-D", "warnings"],
        ]
        .concat(),
    )?;
    for cpu in ["max", "cortex-a53"] {
        run_with_env(
            env!("CARGO"),
            &[&["test", "--release"][..], &core].concat(),
            &[
                LINKER,
                (
                    "CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER",
                    "qemu-aarch64 -L /usr/aarch64-linux-gnu",
                ),
                ("QEMU_CPU", cpu),
            ],
        )?;
    }
    Ok(())
}

/// The cross linker both commands build with.
const LINKER: (&str, &str) = (
    "CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER",
    "aarch64-linux-gnu-gcc",
);

/// Installs the target, QEMU and the cross linker where missing.
fn ensure_tools() -> Result<(), String> {
    ensure_targets(&[AARCH64])?;
    ensure_apt("qemu-aarch64", &["qemu-user"])?;
    ensure_apt(
        "aarch64-linux-gnu-gcc",
        &["gcc-aarch64-linux-gnu", "libc6-dev-arm64-cross"],
    )
}

/// Instructions per encoder call on aarch64, tile kernel against block
/// kernel: core's `encode_count` example under qemu-aarch64 (`max` CPU,
/// with `dotprod`), run once with one call and once with two; the
/// difference is one call, without start-up and model loading.
pub fn count() -> Result<(), String> {
    ensure_tools()?;
    run_with_env(
        env!("CARGO"),
        &[
            "build",
            "--release",
            "-p",
            "pcrnet-core",
            "--example",
            "encode_count",
            "--target",
            AARCH64,
        ],
        &[LINKER],
    )?;
    let binary = root()
        .join("target")
        .join(AARCH64)
        .join("release/examples/encode_count");
    let binary = binary.to_str().ok_or("the build path is not UTF-8")?;
    println!("| widths | tile kernel | block kernel | tile / block |");
    println!("|---|---|---|---|");
    for widths in ["small", "paper"] {
        let mut per_call = Vec::new();
        for kernel in ["tile", "host"] {
            let once = instructions(binary, &[widths, kernel, "1"])?;
            let twice = instructions(binary, &[widths, kernel, "2"])?;
            per_call.push(twice.saturating_sub(once));
        }
        let [tile, block] = per_call[..] else {
            return Err("two counts expected".into());
        };
        println!(
            "| {widths} | {:.2} M | {:.2} M | {:.2}x |",
            tile as f64 / 1e6,
            block as f64 / 1e6,
            tile as f64 / block.max(1) as f64
        );
    }
    Ok(())
}

/// Guest instructions the example runs with `args`, from QEMU's log
/// (`-d in_asm,exec,nochain`): each translation block is listed once with
/// its instructions when translated, then once per execution (no chaining,
/// so every execution is logged); the sum over executions of each block's
/// length is the count.
fn instructions(binary: &str, args: &[&str]) -> Result<u64, String> {
    let mut child = Command::new("qemu-aarch64")
        .args(["-L", "/usr/aarch64-linux-gnu", "-cpu", "max"])
        .args(["-d", "in_asm,exec,nochain", "-D", "/dev/stdout", binary])
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-aarch64: {e}"))?;
    let log = child.stdout.take().ok_or("no log from qemu-aarch64")?;
    let hex = |s: &str| u64::from_str_radix(s.trim_start_matches("0x"), 16).ok();
    let (mut lengths, mut block, mut total) = (HashMap::new(), None::<(u64, u64)>, 0u64);
    for line in BufReader::new(log).lines() {
        let line = line.map_err(|e| format!("reading QEMU's log: {e}"))?;
        if let Some(rest) = line.strip_prefix("Trace ") {
            // `Trace 0: 0x... [flags/pc/...] symbol`: the guest pc second.
            let pc = rest.split('[').nth(1).and_then(|f| f.split('/').nth(1));
            if let Some(n) = pc.and_then(hex).and_then(|pc| lengths.get(&pc)) {
                total += n;
            }
        } else if line.starts_with("IN:") {
            block = Some((0, 0));
        } else if let (Some((start, n)), true) = (block.as_mut(), line.starts_with("0x")) {
            if *n == 0 {
                *start = line.split(':').next().and_then(hex).unwrap_or(0);
            }
            *n += 1;
        } else if let Some((start, n)) = block.take().filter(|&(_, n)| n > 0) {
            lengths.insert(start, n);
        }
    }
    let status = child
        .wait()
        .map_err(|e| format!("waiting for qemu-aarch64: {e}"))?;
    if !status.success() {
        return Err(format!("encode_count {} failed ({status})", args.join(" ")));
    }
    Ok(total)
}
