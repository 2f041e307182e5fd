//! `cargo xtask ci`: every check CI runs, in order, with the minutes of
//! each step printed at the end.

use crate::{
    TARGET, aarch64, c_example, c_header, cargo, cores, ensure_target, fuzz, minimal, no_panic,
    qemu_test, root, run_in, run_with_env,
};

/// Seconds each fuzz target runs in CI (a smoke run that also replays the
/// corpora; campaigns: `cargo xtask fuzz 3600`).
const CI_FUZZ_SECONDS: u64 = 30;

/// The crates built for the device, outside the host workspace.
const FIRMWARE_CRATES: [&str; 4] = [
    "firmware-example",
    "examples/minimal-firmware",
    "tests/firmware",
    "tests/no-panic",
];

pub(crate) fn ci() -> Result<(), String> {
    let mut steps = Steps::default();
    steps.time("host lints (fmt, clippy)", || {
        ensure_target()?;
        cargo(&["fmt", "--all", "--", "--check"])?;
        cargo(&[
            "clippy",
            "--workspace",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ])
    })?;
    steps.time("firmware crates (fmt, clippy, defmt build)", || {
        for dir in FIRMWARE_CRATES {
            let dir = root().join(dir);
            run_in(&dir, env!("CARGO"), &["fmt", "--", "--check"])?;
            run_in(
                &dir,
                env!("CARGO"),
                &["clippy", "--release", "--", "-D", "warnings"],
            )?;
        }
        run_in(
            &root().join("firmware-example"),
            env!("CARGO"),
            &["build", "--release", "--features", "defmt"],
        )
    })?;
    steps.time("no_std build and no-panic proof", || {
        cargo(&["build", "-p", "pcrnet-core", "--target", TARGET])?;
        no_panic::run(&root())
    })?;
    steps.time("C header, C API and device clippy", || {
        c_header(true)?;
        cargo(&[
            "build",
            "-p",
            "pcrnet-capi",
            "--release",
            "--target",
            TARGET,
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
        ])
    })?;
    steps.time("docs", || {
        run_with_env(
            env!("CARGO"),
            &["doc", "--workspace", "--no-deps"],
            &[("RUSTDOCFLAGS", "-D warnings")],
        )
    })?;
    steps.time("publish dry-run (pcrnet-core, pcrnet-io)", || {
        // Both packages as crates.io would build them: pcrnet-io against
        // the packaged pcrnet-core, each from its own file list.
        forget_unpacked_packages(&["pcrnet-core", "pcrnet-io"])?;
        cargo(&[
            "publish",
            "--dry-run",
            "--allow-dirty",
            "-p",
            "pcrnet-core",
            "-p",
            "pcrnet-io",
        ])
    })?;
    steps.time("QEMU harness, Cortex-M4F (qemu-test)", qemu_test)?;
    steps.time("QEMU harness, other cores (cores)", cores)?;
    steps.time("C example under QEMU", c_example)?;
    steps.time("minimal firmware (Rust and C) under QEMU", || {
        minimal::run(&root())
    })?;
    steps.time("aarch64 kernels under qemu-aarch64", aarch64::test)?;
    steps.time("fuzzing", || {
        run_in(
            &root().join("fuzz"),
            env!("CARGO"),
            &["fmt", "--", "--check"],
        )?;
        fuzz::run(&root(), CI_FUZZ_SECONDS)
    })?;
    steps.time("host tests (cargo test --workspace)", || {
        cargo(&["test", "--workspace"])
    })?;
    steps.report();
    Ok(())
}

/// The wall-clock time of each of `ci`'s steps, printed at the end: where
/// a run's minutes go.
/// Removes what earlier dry-runs unpacked of our own packages into
/// `$CARGO_HOME/registry/src`.
///
/// A multi-package `cargo publish --dry-run` serves the packaged crates
/// from a temporary registry under `target/package` and unpacks them into
/// `$CARGO_HOME/registry/src/<hash of that path>/NAME-VERSION`. A directory
/// already there is reused without comparing it with the new package, so on
/// a machine whose cargo home outlives the checkout, pcrnet-io was verified
/// against an old pcrnet-core (the cause of a failed CI run: `unresolved
/// import pcrnet_core::scene`; the same cargo behaviour as
/// 0xMiden/miden-vm#2530). Only directories named after our packages are
/// removed; they never come from crates.io.
fn forget_unpacked_packages(packages: &[&str]) -> Result<(), String> {
    let cargo_home = std::env::var_os("CARGO_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME").map(|home| std::path::Path::new(&home).join(".cargo"))
        });
    let Some(cargo_home) = cargo_home else {
        return Ok(());
    };
    let Ok(registries) = std::fs::read_dir(cargo_home.join("registry").join("src")) else {
        return Ok(());
    };
    for registry in registries.flatten() {
        let Ok(unpacked) = std::fs::read_dir(registry.path()) else {
            continue;
        };
        for entry in unpacked.flatten() {
            let name = entry.file_name();
            let name = name.to_string_lossy();
            let ours = packages.iter().any(|package| {
                name.strip_prefix(package)
                    .and_then(|rest| rest.strip_prefix('-'))
                    .is_some_and(|version| version.starts_with(|c: char| c.is_ascii_digit()))
            });
            if ours {
                std::fs::remove_dir_all(entry.path()).map_err(|error| {
                    format!(
                        "removing the stale unpacked package {}: {error}",
                        entry.path().display()
                    )
                })?;
            }
        }
    }
    Ok(())
}

#[derive(Default)]
struct Steps(Vec<(&'static str, std::time::Duration)>);

impl Steps {
    /// Runs `step`, recording its time under `name`.
    fn time(
        &mut self,
        name: &'static str,
        step: impl FnOnce() -> Result<(), String>,
    ) -> Result<(), String> {
        let started = std::time::Instant::now();
        let result = step();
        self.0.push((name, started.elapsed()));
        result
    }

    /// The table of steps and their minutes.
    fn report(&self) {
        println!("\n| CI step | minutes |\n|---|---|");
        for (name, t) in &self.0 {
            println!("| {name} | {:.1} |", t.as_secs_f64() / 60.0);
        }
        let total: std::time::Duration = self.0.iter().map(|(_, t)| *t).sum();
        println!("| total | {:.1} |", total.as_secs_f64() / 60.0);
    }
}
