//! Cross-compiling the device runner and running it under QEMU.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

use crate::vectors::PSRAM_BASE;

/// The Cortex-M target.
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// The workspace root (parent of `tests/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// Builds a firmware crate (release) and returns its ELF.
pub fn build_firmware(dir: &Path, bin: &str, features: &[&str]) -> anyhow::Result<PathBuf> {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(dir).args(["build", "--release"]);
    if !features.is_empty() {
        cmd.args(["--features", &features.join(",")]);
    }
    // The host workspace's target dir would mix host and device artefacts.
    cmd.env_remove("CARGO_TARGET_DIR");
    let status = cmd
        .status()
        .with_context(|| format!("running cargo in {}", dir.display()))?;
    if !status.success() {
        bail!("building {} failed ({status})", dir.display());
    }
    Ok(dir.join("target").join(TARGET).join("release").join(bin))
}

/// The QEMU command line for an ELF, optionally with a file loaded into PSRAM.
pub fn qemu_command(elf: &Path, psram_file: Option<&Path>) -> Command {
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args([
        "-machine",
        "mps2-an386",
        "-cpu",
        "cortex-m4",
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        "-icount",
        "shift=0,align=off,sleep=off",
        "-kernel",
    ]);
    cmd.arg(elf);
    if let Some(f) = psram_file {
        cmd.arg("-device").arg(format!(
            "loader,file={},addr={PSRAM_BASE:#x},force-raw=on",
            f.display()
        ));
    }
    cmd
}

/// Runs a command, killing it after `timeout` (a wrong machine or a hang
/// never ends on its own). Returns stdout; fails on timeout or non-zero exit.
pub fn run_with_timeout(mut cmd: Command, timeout: Duration) -> anyhow::Result<String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context(
            "starting qemu-system-arm (is it installed? `cargo xtask qemu-test` installs it)",
        )?;
    let mut stdout = child.stdout.take().context("qemu stdout")?;
    let mut stderr = child.stderr.take().context("qemu stderr")?;
    let out_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break Some(status);
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let out = out_reader.join().unwrap_or_default();
    let err = err_reader.join().unwrap_or_default();
    match status {
        None => bail!(
            "QEMU timed out after {timeout:?}; last output:\n{}\n{err}",
            tail(&out)
        ),
        Some(s) if !s.success() => bail!("QEMU exited with {s}:\n{}\n{err}", tail(&out)),
        Some(_) => Ok(out),
    }
}

fn tail(s: &str) -> String {
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(10)..].join("\n")
}
