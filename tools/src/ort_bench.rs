//! `cargo xtask ort-bench [DATA]`: our network beside ONNX Runtime on the
//! same weights and clouds, one thread, printing the time ratios (issue 13).
//!
//! ONNX Runtime, onnx and numpy are installed with pip into a virtual
//! environment under `target/ort-venv` (pinned versions, first run only);
//! nothing of it is on the test path. `train-host/eval/examples/ort_bench.rs`
//! writes the weights, blobs and clouds; `tools/ort_bench.py` rebuilds the
//! network as an ONNX graph, checks its f32 outputs against ours, quantizes
//! it with ONNX Runtime's static quantizer, times it in turn with ours round
//! by round (our rounds run in the example's `serve` mode, kept waiting
//! between them) and prints the table.
//!
//! Then ICP: Open3D (`open3d-cpu`, pinned) is installed into the same
//! environment when its wheel installs here, and `tools/icp_bench.py`
//! runs its point-to-point ICP on the pairs our side registered (see the
//! example's docs). Without Open3D that comparison is skipped, saying so.
//!
//! With `--avx2`, both sides run as on a CPU with AVX2 but no AVX-512 or
//! AVX-VNNI, and with `--avx-vnni` as on one with AVX-VNNI but no
//! AVX-512: `tools/cpuid/mask.c`, built with gcc into `target/` and
//! preloaded into the script (and so into our side, which it starts),
//! hides those features from every feature test through Linux's CPUID
//! faulting. The ICP comparison is left out then.

use std::path::Path;

/// What pip installs (the versions measured in the README).
const PACKAGES: [&str; 3] = ["onnxruntime==1.32.0", "onnx==1.23.2", "numpy==2.4.6"];

/// Open3D, for the ICP comparison (its CPU-only wheel).
const OPEN3D: &str = "open3d-cpu==0.19.0";

/// A CPU class the benchmark can pretend to run on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cpu {
    /// AVX2, no AVX-512 or AVX-VNNI (AMD Zen 1-3, Intel Haswell to
    /// Comet Lake).
    Avx2,
    /// AVX-VNNI, no AVX-512 (Intel client cores from Alder Lake on).
    AvxVnni,
}

impl Cpu {
    /// The preloaded library's name, gcc's extra flags and what the run
    /// says.
    fn parts(self) -> (&'static str, &'static [&'static str], &'static str) {
        match self {
            Cpu::Avx2 => ("avx2_only", &[], "AVX-512 and AVX-VNNI hidden"),
            Cpu::AvxVnni => ("avx_vnni", &["-DKEEP_AVX_VNNI"], "AVX-512 hidden"),
        }
    }
}

/// The benchmark on `data` (ModelNet10 by default), on the CPU's own
/// features or as on `cpu`.
pub fn run(root: &Path, data: Option<&str>, cpu: Option<Cpu>) -> Result<(), String> {
    let venv = root.join("target/ort-venv");
    let python = venv.join("bin/python");
    let python = python.to_str().ok_or("the workspace path is not UTF-8")?;
    let ready = std::process::Command::new(python)
        .args(["-c", "import onnxruntime, onnx, numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        let venv = venv.to_str().ok_or("the workspace path is not UTF-8")?;
        crate::run("python3", &["-m", "venv", venv])?;
        let mut args = vec!["-m", "pip", "install", "--quiet"];
        args.extend(PACKAGES);
        crate::run(python, &args)?;
    }
    let out = "target/ort-bench";
    let default_data = root.join("../shared/data/ModelNet10");
    let data = match data {
        Some(d) => Some(d.to_owned()),
        None => default_data
            .is_dir()
            .then(|| default_data.to_string_lossy().into_owned()),
    };
    let mut args = vec![
        "run",
        "--release",
        "-q",
        "-p",
        "pcrnet-eval",
        "--example",
        "ort_bench",
        "--",
        out,
    ];
    if let Some(d) = &data {
        args.extend(["--data", d.as_str()]);
    }
    crate::cargo(&args)?;
    let ours = root.join("target/release/examples/ort_bench");
    let ours = ours.to_str().ok_or("the workspace path is not UTF-8")?;
    if let Some(cpu) = cpu {
        let (name, flags, hidden) = cpu.parts();
        let shim = format!("target/{name}.so");
        let source = "tools/cpuid/mask.c";
        let mut args = vec!["-O2", "-shared", "-fPIC", "-o", shim.as_str(), source];
        args.extend(flags);
        crate::run("gcc", &args)?;
        let preload = root.join(&shim);
        let preload = preload.to_str().ok_or("the workspace path is not UTF-8")?;
        println!("{hidden} ({shim}, from {source})");
        return crate::run_with_env(
            python,
            &["tools/ort_bench.py", out, ours],
            &[("LD_PRELOAD", preload)],
        );
    }
    crate::run(python, &["tools/ort_bench.py", out, ours])?;
    let has_open3d = |python: &str| {
        std::process::Command::new(python)
            .args(["-c", "import open3d"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !has_open3d(python) {
        let installed = crate::run(
            python,
            &["-m", "pip", "install", "--quiet", OPEN3D, PACKAGES[2]],
        );
        if let Err(e) = installed.and_then(|()| {
            has_open3d(python)
                .then_some(())
                .ok_or_else(|| "installed but does not import".to_string())
        }) {
            eprintln!("Open3D ({OPEN3D}) is not available here ({e}): ICP comparison skipped");
            return Ok(());
        }
    }
    println!();
    crate::run(python, &["tools/icp_bench.py", out, ours])
}
