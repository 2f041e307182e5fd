//! Developer commands for the workspace (the xtask pattern): `cargo xtask <command>`.
//!
//! Every command installs what it needs and is missing (the thumbv7em
//! target through rustup, QEMU through apt-get), so a fresh machine needs
//! only a Rust toolchain.

mod aarch64;
mod ci;
#[cfg(test)]
mod circles;
mod fuzz;
mod minimal;
mod no_panic;
mod ort_bench;
mod profile;

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use pcrnet_qemu_tests::qemu::BOARDS;

/// The default board's target (Cortex-M4F).
const TARGET: &str = BOARDS[0].target;

const HELP: &str = "\
cargo xtask <command>

  ci            everything CI checks: fmt, clippy -D warnings (host and
                firmware crates), docs, the publish dry-run of pcrnet-core
                and pcrnet-io, core for thumbv7em-none-eabihf,
                the no-panic proof, the C header, the QEMU harness on
                every core, the C example, the minimal examples (Rust
                and C), the aarch64 kernels, every fuzz target for
                30 s, then the host tests
  demo          the main job: register the shipped source with the trained
                embedded default (int8) through the device pipeline, and say
                whether the pose is reliable; extra arguments go to
                `pcrnet register`
  qemu-test     run core on an emulated Cortex-M4F and compare every output
                with the host bit for bit; then prove a changed rounding on
                the device is caught; then instructions per MAC layer by
                layer (M4F and M7)
  cores         the QEMU harness on the other cores (Cortex-M3 mps2-an385,
                M7 mps2-an500, M33 mps2-an505, RISC-V rv32imac virt: cases
                up to 1,024 points, no paper-size model; M0 microbit: the
                small random models), each bit-exact with the host
  aarch64-test  pcrnet-core's tests (with `std`: the NEON and SDOT host
                kernels, tile, head and block, each against the portable
                one) built for
                aarch64-unknown-linux-gnu and run under qemu-aarch64 on a
                CPU with the dot-product extension (max) and one without
                (Cortex-A53)
  aarch64-count instructions per encoder call on aarch64, tile kernel
                against block kernel (core's encode_count example under
                qemu-aarch64 on a CPU with the dot-product extension,
                counted from QEMU's translation log): 1,024 points,
                random models of the embedded and the paper's widths
  firmware-run  build firmware-example and run it under QEMU
  profile       run firmware-example under QEMU with instruction tracing
                and print the instructions per function and hottest blocks
  no-panic      link-time proof that no panic is reachable from core's
                entry points or the C API (tests/no-panic, on the M4F,
                M0, M3 and M33 targets); on failure, lists each call into
                panic code with its inline chain
  fuzz [SECONDS]
                every fuzz target (fuzz/: blobs, sealed blobs, clouds, the
                C API, each reader) for SECONDS each (default 60) with
                cargo-fuzz on nightly, from generated seed corpora and the
                committed regressions; prints executions and coverage
  size          flash and static RAM of firmware-example
  c-example     build the C firmware example (firmware-c/, arm-none-eabi-gcc
                linking libpcrnet.a), run it under QEMU and compare every
                result with the host bit for bit
  minimal       build the minimal firmware examples as a user would
                (examples/minimal-firmware with cargo, examples/minimal-c
                with make) and run each under QEMU (mps2-an386): each
                must print a reliable pose
  c-header [--check]
                write capi/include/pcrnet.h from the C API crate (cbindgen);
                --check fails if the committed header differs
  bench         host benchmarks (criterion): encoder throughput, training step
  ort-bench [DATA] [--avx2 | --avx-vnni]
                our f32 and int8 network beside ONNX Runtime on the same
                weights and clouds (the shipped embedded default and a
                paper-width model; 50 ModelNet10 test clouds from DATA,
                default ../shared/data/ModelNet10, else generated shapes),
                one thread, printing the time ratios; installs onnxruntime,
                onnx and numpy with pip into target/ort-venv; with --avx2
                both sides as on a CPU without AVX-512 and AVX-VNNI, with
                --avx-vnni as on one with AVX-VNNI but no AVX-512
                (tools/cpuid/mask.c, needs CPUID faulting)
  results [DATA] run the paper's six experiments and `trust` on DATA (default
                ../shared/data; trains the models they need into
                target/experiments) and regenerate RESULTS.md
  help          this text

Missing tools are installed: the Rust targets of the cores and the
nightly toolchain (rustup), cargo-fuzz (cargo install), qemu-system-arm,
qemu-system-misc (RISC-V), qemu-user and gcc-aarch64-linux-gnu (aarch64),
gcc-arm-none-eabi, libnewlib-arm-none-eabi and binutils-arm-none-eabi
(apt-get).
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("ci") => ci::ci(),
        Some("demo") => demo(&args[1..]),
        Some("bench") => cargo(&["bench", "-p", "pcrnet-core", "-p", "pcrnet-train"]),
        Some("ort-bench") => {
            ort_bench_args(&args[1..]).and_then(|(data, cpu)| ort_bench::run(&root(), data, cpu))
        }
        Some("qemu-test") => qemu_test(),
        Some("cores") => cores(),
        Some("results") => results(args.get(1).map_or("../shared/data", String::as_str)),
        Some("firmware-run") => firmware_run(),
        Some("aarch64-test") => aarch64::test(),
        Some("aarch64-count") => aarch64::count(),
        Some("profile") => ensure_target()
            .and_then(|()| ensure_qemu())
            .and_then(|()| profile::run(&root())),
        Some("c-example") => c_example(),
        Some("minimal") => minimal::run(&root()),
        Some("c-header") => c_header(args.get(1).map(String::as_str) == Some("--check")),
        Some("no-panic") => no_panic::run(&root()),
        Some("fuzz") => fuzz_seconds(&args[1..]).and_then(|s| fuzz::run(&root(), s)),
        Some("size") => ensure_target().and_then(|()| harness(&["size"])),
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

/// `ort-bench`'s arguments: an optional data folder and at most one CPU
/// flag. An unknown flag, a second folder or a second CPU flag is an
/// error (not a silent choice between them).
fn ort_bench_args(args: &[String]) -> Result<(Option<&str>, Option<ort_bench::Cpu>), String> {
    let (mut data, mut cpu) = (None, None);
    for a in args {
        let flag = match a.as_str() {
            "--avx2" => Some(ort_bench::Cpu::Avx2),
            "--avx-vnni" => Some(ort_bench::Cpu::AvxVnni),
            flag if flag.starts_with('-') => {
                return Err(format!("ort-bench: unknown flag `{flag}`\n\n{HELP}"));
            }
            path => {
                if let Some(first) = data.replace(path) {
                    return Err(format!(
                        "ort-bench takes one data folder, given `{first}` and `{path}`\n\n{HELP}"
                    ));
                }
                None
            }
        };
        if let Some(flag) = flag
            && cpu.replace(flag).is_some()
        {
            return Err(format!(
                "ort-bench takes one of --avx2 and --avx-vnni\n\n{HELP}"
            ));
        }
    }
    Ok((data, cpu))
}

/// `fuzz`'s argument: seconds per target (60 without one).
fn fuzz_seconds(args: &[String]) -> Result<u64, String> {
    match args {
        [] => Ok(60),
        [seconds] => seconds.parse().map_err(|_| {
            format!("fuzz takes a number of seconds per target, not `{seconds}`\n\n{HELP}")
        }),
        _ => Err(format!(
            "fuzz takes one number of seconds per target\n\n{HELP}"
        )),
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

/// Installs the Cortex-M4F target if rustup does not list it yet.
fn ensure_target() -> Result<(), String> {
    ensure_targets(&[TARGET])
}

/// Installs the Rust targets rustup does not list yet.
fn ensure_targets(targets: &[&str]) -> Result<(), String> {
    let out = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .map_err(|e| format!("cannot run rustup: {e}"))?;
    let installed = String::from_utf8_lossy(&out.stdout);
    let missing: Vec<&str> = targets
        .iter()
        .copied()
        .filter(|t| !installed.lines().any(|l| l.trim() == *t))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    let mut args = vec!["target", "add"];
    args.extend(missing);
    run("rustup", &args)
}

/// The QEMU harness on every other core (a subset of the cases: no
/// paper-size model, clouds up to 1,024 points; the micro:bit's 16 KiB of
/// RAM takes the random models up to 300 points), each bit-exact with the host.
fn cores() -> Result<(), String> {
    let others = &BOARDS[1..];
    let targets: Vec<&str> = others.iter().map(|b| b.target).collect();
    ensure_targets(&targets)?;
    ensure_qemu()?;
    if others.iter().any(|b| b.qemu == "qemu-system-riscv32") {
        ensure_apt("qemu-system-riscv32", &["qemu-system-misc"])?;
    }
    for board in others {
        harness(&["run", "--board", board.machine])?;
    }
    Ok(())
}

/// Installs Debian `packages` through apt-get unless `probe` runs.
fn ensure_apt(probe: &str, packages: &[&str]) -> Result<(), String> {
    let found = Command::new(probe)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if found {
        return Ok(());
    }
    run("apt-get", &["update"])?;
    let mut args = vec!["install", "-y", "--no-install-recommends"];
    args.extend_from_slice(packages);
    run("apt-get", &args)
}

fn ensure_qemu() -> Result<(), String> {
    ensure_apt("qemu-system-arm", &["qemu-system-arm"])
}

/// The C example, compared with the host by the harness.
fn c_example() -> Result<(), String> {
    ensure_target()?;
    ensure_qemu()?;
    ensure_arm_gcc()?;
    harness(&["c-example"])
}

/// The C examples' toolchain: GCC for Arm, newlib, make.
fn ensure_arm_gcc() -> Result<(), String> {
    ensure_apt(
        "arm-none-eabi-gcc",
        &["gcc-arm-none-eabi", "libnewlib-arm-none-eabi", "make"],
    )
}

/// Runs the harness binary (tests/) in release mode.
fn harness(args: &[&str]) -> Result<(), String> {
    let mut all = vec!["run", "--release", "-p", "pcrnet-qemu-tests", "--"];
    all.extend_from_slice(args);
    cargo(&all)
}

fn qemu_test() -> Result<(), String> {
    ensure_target()?;
    ensure_qemu()?;
    harness(&["run"])?;
    harness(&["run", "--mutate-device-rounding"])?;
    layers()
}

/// Instructions per MAC layer by layer on the Cortex-M4F and the M7 (the
/// same binary: the counts agree), every prefix model bit-exact.
fn layers() -> Result<(), String> {
    harness(&["layers"])?;
    harness(&["layers", "--board", "mps2-an500"])
}

fn firmware_run() -> Result<(), String> {
    ensure_target()?;
    ensure_qemu()?;
    run_in(
        &root().join("firmware-example"),
        env!("CARGO"),
        &["run", "--release"],
    )
}

/// Runs a command in the workspace root with extra environment variables.
fn run_with_env(program: &str, args: &[&str], env: &[(&str, &str)]) -> Result<(), String> {
    run_in_with_env(&root(), program, args, env)
}

/// Runs a command in `dir`.
fn run_in(dir: &Path, program: &str, args: &[&str]) -> Result<(), String> {
    run_in_with_env(dir, program, args, &[])
}

fn run_in_with_env(
    dir: &Path,
    program: &str,
    args: &[&str],
    env: &[(&str, &str)],
) -> Result<(), String> {
    let shown: Vec<String> = env.iter().map(|(k, v)| format!("{k}={v} ")).collect();
    println!("$ {}{program} {}", shown.concat(), args.join(" "));
    let status = Command::new(program)
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .status()
        .map_err(|e| format!("cannot start {program}: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{program} {}` failed ({status})", args.join(" ")))
    }
}

/// Runs the host CLI, `pcrnet <args>`, built in release mode.
fn pcrnet(args: &[&str]) -> Result<(), String> {
    let mut all = vec![
        "run",
        "--release",
        "-p",
        "pcrnet-cli",
        "--bin",
        "pcrnet",
        "--",
    ];
    all.extend_from_slice(args);
    cargo(&all)
}

/// Every experiment of issue 5 on `data`, then RESULTS.md from their reports.
fn results(data: &str) -> Result<(), String> {
    pcrnet(&["experiment", "all", "--data", data])?;
    pcrnet(&["results"])
}

/// The main job on the embedded default: register the shipped source onto
/// the template stored in the trained int8 model, with the device pipeline
/// (network, flip hypotheses, ICP, residual: what the firmware runs, bit
/// for bit), and say whether the pose can be trusted.
fn demo(extra: &[String]) -> Result<(), String> {
    let mut args = vec![
        "register",
        "models/embedded-default-source.xyz",
        "--model",
        "models/embedded-default-int8.pcrn",
    ];
    args.extend(extra.iter().map(String::as_str));
    pcrnet(&args)
}

/// The C API's header, generated from `capi/` with `capi/cbindgen.toml`:
/// written, or with `check` compared with the committed file.
fn c_header(check: bool) -> Result<(), String> {
    let dir = root().join("capi");
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml"))
        .map_err(|e| format!("capi/cbindgen.toml: {e}"))?;
    let bindings = cbindgen::Builder::new()
        .with_crate(&dir)
        .with_config(config)
        .generate()
        .map_err(|e| format!("generating the C header: {e}"))?;
    let mut text = Vec::new();
    bindings.write(&mut text);
    let path = dir.join("include").join("pcrnet.h");
    if check {
        let committed = std::fs::read(&path).unwrap_or_default();
        if committed != text {
            return Err(format!(
                "{} is stale: run `cargo xtask c-header` and commit it",
                path.display()
            ));
        }
        println!("{} is up to date", path.display());
        return Ok(());
    }
    std::fs::write(&path, &text).map_err(|e| format!("writing {}: {e}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(args: &[&str]) -> Vec<String> {
        args.iter().map(|a| a.to_string()).collect()
    }

    /// A folder and a CPU flag in either order; an unknown flag, two
    /// folders or two CPU flags are errors that name the problem.
    #[test]
    fn ort_bench_arguments() {
        let ok = |args: &[&str]| {
            let args = strings(args);
            ort_bench_args(&args).map(|(d, c)| (d.map(str::to_owned), c))
        };
        assert_eq!(ok(&[]), Ok((None, None)));
        assert_eq!(
            ok(&["data", "--avx2"]),
            Ok((Some("data".into()), Some(ort_bench::Cpu::Avx2)))
        );
        assert_eq!(
            ok(&["--avx-vnni", "data"]),
            Ok((Some("data".into()), Some(ort_bench::Cpu::AvxVnni)))
        );
        let err = |args: &[&str]| ort_bench_args(&strings(args)).unwrap_err();
        assert!(err(&["--avx512"]).contains("unknown flag `--avx512`"));
        assert!(err(&["-v"]).contains("unknown flag `-v`"));
        assert!(err(&["a", "b"]).contains("given `a` and `b`"));
        assert!(err(&["--avx2", "--avx-vnni"]).contains("one of --avx2 and --avx-vnni"));
        assert!(err(&["--avx2", "--avx2"]).contains("one of"));
    }

    /// Each `<!-- SNIPPET: PATH -->` in the README is followed by a fenced
    /// block holding exactly PATH's text, so the README's firmware code is
    /// the code CI builds and runs (`cargo xtask minimal`).
    #[test]
    fn readme_snippets_are_the_examples() {
        let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
        let mut found = 0;
        for (at, _) in readme.match_indices("<!-- SNIPPET: ") {
            let rest = &readme[at + "<!-- SNIPPET: ".len()..];
            let (path, rest) = rest.split_once(" -->\n```").unwrap();
            let (_lang, rest) = rest.split_once('\n').unwrap();
            let (block, _) = rest.split_once("```").unwrap();
            let file = std::fs::read_to_string(root().join(path)).unwrap();
            assert_eq!(
                block, file,
                "README's copy of {path} differs: paste the file again"
            );
            found += 1;
        }
        assert_eq!(found, 2, "the README shows the Rust and the C example");
    }

    /// Seconds per fuzz target: 60 by default, a number, or an error.
    #[test]
    fn fuzz_arguments() {
        assert_eq!(fuzz_seconds(&[]), Ok(60));
        assert_eq!(fuzz_seconds(&strings(&["15"])), Ok(15));
        assert!(
            fuzz_seconds(&strings(&["soon"]))
                .unwrap_err()
                .contains("not `soon`")
        );
        assert!(fuzz_seconds(&strings(&["1", "2"])).is_err());
    }
}
