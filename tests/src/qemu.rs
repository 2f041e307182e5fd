//! Cross-compiling the device runner and running it under QEMU.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// An emulated board the device runner runs on: a QEMU machine, its core,
/// the Rust target built for it and the runner's board feature (see
/// `firmware-example/src/board.rs` for the memory maps).
#[derive(Debug)]
pub struct Board {
    /// QEMU system emulator.
    pub qemu: &'static str,
    /// QEMU machine (`-machine`).
    pub machine: &'static str,
    /// QEMU CPU (`-cpu`).
    pub cpu: &'static str,
    /// The core, as the README's table names it.
    pub core: &'static str,
    /// Rust target.
    pub target: &'static str,
    /// Cargo feature of the device crates selecting the board, if not the default.
    pub feature: Option<&'static str>,
    /// Where QEMU loads the test vectors (the board's data region: PSRAM
    /// on the MPS2 boards, the end of flash on the micro:bit).
    pub data_base: u32,
    /// Size of that region.
    pub data_len: usize,
    /// Which cases run on it.
    pub cases: CaseSet,
    /// Which int8 kernel `pcrnet-core` compiles for the target.
    pub kernel: &'static str,
}

/// Every board the harness supports; the first is the default, where the
/// full case set and the mutation check run.
pub const BOARDS: [Board; 6] = [
    Board {
        qemu: "qemu-system-arm",
        machine: "mps2-an386",
        cpu: "cortex-m4",
        core: "Cortex-M4F",
        target: "thumbv7em-none-eabihf",
        feature: None,
        data_base: 0x2100_0000,
        data_len: 16 << 20,
        cases: CaseSet::Full,
        kernel: "DSP (SMLAD)",
    },
    Board {
        qemu: "qemu-system-arm",
        machine: "mps2-an385",
        cpu: "cortex-m3",
        core: "Cortex-M3",
        target: "thumbv7m-none-eabi",
        feature: None,
        data_base: 0x2100_0000,
        data_len: 16 << 20,
        cases: CaseSet::Subset,
        kernel: "portable, soft float",
    },
    Board {
        qemu: "qemu-system-arm",
        machine: "mps2-an500",
        cpu: "cortex-m7",
        core: "Cortex-M7",
        target: "thumbv7em-none-eabihf",
        feature: Some("mps2-an500"),
        data_base: 0x6000_0000,
        data_len: 16 << 20,
        cases: CaseSet::Subset,
        kernel: "DSP (SMLAD)",
    },
    Board {
        qemu: "qemu-system-arm",
        machine: "mps2-an505",
        cpu: "cortex-m33",
        core: "Cortex-M33",
        target: "thumbv8m.main-none-eabihf",
        feature: Some("mps2-an505"),
        data_base: 0x8000_0000,
        data_len: 16 << 20,
        cases: CaseSet::Subset,
        kernel: "portable",
    },
    Board {
        qemu: "qemu-system-arm",
        machine: "microbit",
        cpu: "cortex-m0",
        core: "Cortex-M0",
        target: "thumbv6m-none-eabi",
        feature: Some("microbit"),
        data_base: 0x0002_0000,
        data_len: 128 << 10,
        cases: CaseSet::Small,
        kernel: "portable, soft float",
    },
    Board {
        qemu: "qemu-system-riscv32",
        machine: "virt",
        cpu: "rv32",
        core: "RISC-V rv32imac",
        target: "riscv32imac-unknown-none-elf",
        feature: None,
        data_base: 0x8100_0000,
        data_len: 16 << 20,
        cases: CaseSet::Subset,
        kernel: "portable, soft float",
    },
];

/// The cases a board runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaseSet {
    /// Every model and cloud (the default board).
    Full,
    /// No paper-size model, clouds up to 1,024 points: every code path in
    /// a fraction of the time.
    Subset,
    /// The random models on clouds up to 300 points: what fits 128 KiB of
    /// data and 16 KiB of RAM.
    Small,
}

/// The board QEMU calls `machine`.
pub fn board(machine: &str) -> anyhow::Result<&'static Board> {
    BOARDS
        .iter()
        .find(|b| b.machine == machine)
        .with_context(|| {
            let names: Vec<&str> = BOARDS.iter().map(|b| b.machine).collect();
            format!("unknown board {machine} (one of {})", names.join(", "))
        })
}

impl Board {
    /// Whether this is the default board (full case set, mutation check).
    pub fn is_default(&self) -> bool {
        self.machine == BOARDS[0].machine
    }
}

/// The workspace root (parent of `tests/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// Builds a firmware crate (release) for `board` and returns its ELF. The
/// default board builds into the crate's `target/`; the others into
/// `target/<machine>/`, so switching boards does not rebuild.
pub fn build_firmware(
    dir: &Path,
    bin: &str,
    board: &Board,
    features: &[&str],
) -> anyhow::Result<PathBuf> {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    let mut target_dir = dir.join("target");
    if !board.is_default() {
        target_dir = target_dir.join(board.machine);
    }
    cmd.current_dir(dir)
        .args(["build", "--release", "--target", board.target])
        .arg("--target-dir")
        .arg(&target_dir);
    let features: Vec<&str> = features.iter().copied().chain(board.feature).collect();
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
    Ok(target_dir.join(board.target).join("release").join(bin))
}

/// The QEMU command line for an ELF on `board`, optionally with a file
/// loaded into its data region.
pub fn qemu_command(board: &Board, elf: &Path, psram_file: Option<&Path>) -> Command {
    let mut cmd = Command::new(board.qemu);
    if board.qemu == "qemu-system-riscv32" {
        // No firmware: QEMU jumps straight to the ELF's entry.
        cmd.args(["-bios", "none"]);
    }
    cmd.args([
        "-machine",
        board.machine,
        "-cpu",
        board.cpu,
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
            "loader,file={},addr={:#x},force-raw=on",
            f.display(),
            board.data_base
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
        .with_context(|| {
            format!(
                "starting {:?} (is it installed? `cargo xtask qemu-test` and `cargo xtask cores` install it)",
                cmd.get_program()
            )
        })?;
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
