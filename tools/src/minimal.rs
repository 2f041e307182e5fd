//! `cargo xtask minimal`: the minimal firmware examples, built as a user
//! who copied them would (`cargo build --release` in
//! `examples/minimal-firmware`, `make` in `examples/minimal-c`) and run
//! under QEMU's mps2-an386 (Cortex-M4F) with semihosting, as their own
//! runners do; each must exit cleanly having printed `reliable: true` for
//! the shipped model and source.

use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::{TARGET, ensure_arm_gcc, ensure_qemu, ensure_target, run_in};

/// Longest a run may take (each takes well under a second).
const TIMEOUT: Duration = Duration::from_secs(120);

/// Builds and runs both examples.
pub fn run(root: &Path) -> Result<(), String> {
    ensure_target()?;
    ensure_qemu()?;
    ensure_arm_gcc()?;

    let rust = root.join("examples/minimal-firmware");
    run_in(&rust, env!("CARGO"), &["build", "--release"])?;
    let elf = rust.join(format!("target/{TARGET}/release/pcrnet-minimal-firmware"));
    check("examples/minimal-firmware", &elf)?;

    let c = root.join("examples/minimal-c");
    run_in(&c, "make", &[])?;
    check("examples/minimal-c", &c.join("build/minimal.elf"))
}

/// Runs `elf` under QEMU and checks that it exits with 0 and prints a
/// reliable pose.
fn check(name: &str, elf: &Path) -> Result<(), String> {
    let output = qemu(elf)?;
    print!("{output}");
    if output.lines().any(|l| l.trim() == "reliable: true") {
        println!("{name}: reliable pose");
        Ok(())
    } else {
        Err(format!("{name} printed no `reliable: true`"))
    }
}

/// The image's semihosting output under QEMU, or why the run failed (a
/// non-zero exit, a hang).
fn qemu(elf: &Path) -> Result<String, String> {
    let mut child = Command::new("qemu-system-arm")
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4", "-nographic"])
        .args(["-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
    let mut stdout = child.stdout.take().ok_or("no QEMU output")?;
    // Read on a thread: the pipe must drain while the image runs.
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        stdout.read_to_string(&mut text).map(|_| text)
    });
    let started = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if started.elapsed() < TIMEOUT => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Ok(None) => {
                // Our own child, by its handle.
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("{} ran past {TIMEOUT:?}", elf.display()));
            }
            Err(e) => return Err(format!("waiting for QEMU: {e}")),
        }
    };
    let output = reader
        .join()
        .map_err(|_| "reading QEMU's output panicked".to_string())?
        .map_err(|e| format!("reading QEMU's output: {e}"))?;
    if status.success() {
        Ok(output)
    } else {
        Err(format!("{} exited with {status}:\n{output}", elf.display()))
    }
}
