//! Developer commands for the workspace (the xtask pattern): `cargo xtask <command>`.
//!
//! Every command installs what it needs and is missing (the thumbv7em
//! target through rustup, QEMU through apt-get), so a fresh machine needs
//! only a Rust toolchain.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

const TARGET: &str = "thumbv7em-none-eabihf";

const HELP: &str = "\
cargo xtask <command>

  ci          everything CI checks: fmt, clippy -D warnings, host tests,
              core built for thumbv7em-none-eabihf (also with defmt), docs
  demo        the main job on the embedded default (pcrnet demo)
  bench       host benchmarks of the encoder (criterion)
  help        this text
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("ci") => ci(),
        Some("demo") => demo(&args[1..]),
        Some("bench") => cargo(&["bench", "-p", "pcrnet-core", "--bench", "encoder"]),
        Some("help") | None => {
            print!("{HELP}");
            Ok(())
        }
        Some(other) => Err(format!("unknown command `{other}`\n\n{HELP}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// Runs a command in the workspace root, failing on a non-zero exit.
fn run(program: &str, args: &[&str]) -> Result<(), String> {
    run_with_env(program, args, &[])
}

fn cargo(args: &[&str]) -> Result<(), String> {
    run(env!("CARGO"), args)
}

/// Installs the Cortex-M target if rustup does not list it yet.
fn ensure_target() -> Result<(), String> {
    let out = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .map_err(|e| format!("cannot run rustup: {e}"))?;
    if String::from_utf8_lossy(&out.stdout)
        .lines()
        .any(|l| l.trim() == TARGET)
    {
        return Ok(());
    }
    run("rustup", &["target", "add", TARGET])
}

fn ci() -> Result<(), String> {
    ensure_target()?;
    cargo(&["fmt", "--all", "--", "--check"])?;
    cargo(&[
        "clippy",
        "--workspace",
        "--all-targets",
        "--",
        "-D",
        "warnings",
    ])?;
    cargo(&["build", "-p", "pcrnet-core", "--target", TARGET])?;
    cargo(&[
        "build",
        "-p",
        "pcrnet-core",
        "--target",
        TARGET,
        "--features",
        "defmt",
    ])?;
    cargo(&[
        "clippy",
        "-p",
        "pcrnet-core",
        "--target",
        TARGET,
        "--",
        "-D",
        "warnings",
    ])?;
    run_with_env(
        env!("CARGO"),
        &["doc", "--workspace", "--no-deps"],
        &[("RUSTDOCFLAGS", "-D warnings")],
    )?;
    cargo(&["test", "--workspace"])
}

/// Runs a command in the workspace root with extra environment variables.
fn run_with_env(program: &str, args: &[&str], env: &[(&str, &str)]) -> Result<(), String> {
    let shown: Vec<String> = env.iter().map(|(k, v)| format!("{k}={v} ")).collect();
    println!("$ {}{program} {}", shown.concat(), args.join(" "));
    let status = Command::new(program)
        .args(args)
        .envs(env.iter().copied())
        .current_dir(root())
        .status()
        .map_err(|e| format!("cannot start {program}: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{program} {}` failed ({status})", args.join(" ")))
    }
}

fn demo(extra: &[String]) -> Result<(), String> {
    let mut args = vec![
        "run",
        "--release",
        "-p",
        "pcrnet-train",
        "--bin",
        "pcrnet",
        "--",
        "demo",
    ];
    args.extend(extra.iter().map(String::as_str));
    cargo(&args)
}
