//! `cargo xtask fuzz [SECONDS]`: every fuzz target of `fuzz/` (cargo-fuzz,
//! libFuzzer, nightly) for SECONDS each, from seed corpora generated here
//! (valid blobs, clouds and files of every reader's format) plus the
//! inputs committed under `fuzz/regressions/<target>/`, which are replayed
//! first. All targets are built at once, then run as many at a time as
//! there are cores. Prints executions, coverage and corpus size per target.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

use pcrnet_core::format::{CRC_LEN, FORMAT_VERSION, HEADER_LEN};
use pcrnet_core::testing::{random_f32_blob_into, random_int8_blob_into};

/// The targets, in `fuzz/Cargo.toml`'s order.
const TARGETS: [&str; 8] = [
    "blob",
    "blob_sealed",
    "cloud",
    "capi",
    "read_pcd",
    "read_ply",
    "read_off",
    "read_xyz",
];

/// Runs every target for `seconds` (CI: a short run; campaigns: longer).
/// Every target is built first in one `cargo fuzz build` (cargo compiles
/// them side by side); the runs then go as many at a time as there are
/// cores, each libFuzzer process on one thread, so each target still gets
/// its `seconds` of a whole core.
pub fn run(root: &Path, seconds: u64) -> Result<(), String> {
    ensure_tools()?;
    let corpora = root.join("target/fuzz-corpus");
    let seeds = seeds(root)?;
    for target in TARGETS {
        let dir = corpora.join(target);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let regressions = root.join("fuzz/regressions").join(target);
        let mut inputs: Vec<(String, Vec<u8>)> = seeds
            .iter()
            .filter(|(t, _, _)| *t == target)
            .map(|(_, name, bytes)| (format!("seed-{name}"), bytes.clone()))
            .collect();
        if let Ok(entries) = std::fs::read_dir(&regressions) {
            for e in entries.flatten() {
                let bytes = std::fs::read(e.path()).map_err(|err| err.to_string())?;
                inputs.push((
                    format!("regression-{}", e.file_name().to_string_lossy()),
                    bytes,
                ));
            }
        }
        for (name, bytes) in inputs {
            std::fs::write(dir.join(name), bytes).map_err(|e| e.to_string())?;
        }
    }
    crate::run_in(&root.join("fuzz"), "cargo", &["+nightly", "fuzz", "build"])?;
    let jobs = std::thread::available_parallelism().map_or(1, usize::from);
    let next = AtomicUsize::new(0);
    let mut results: Vec<(usize, &str, Result<Stats, String>)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..jobs.min(TARGETS.len()))
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&target) = TARGETS.get(i) else {
                            return done;
                        };
                        let stats = run_target(root, target, &corpora.join(target), seconds);
                        done.push((i, target, stats));
                    }
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| {
                w.join()
                    .unwrap_or_else(|_| vec![(0, "?", Err("a fuzz worker thread panicked".into()))])
            })
            .collect()
    });
    results.sort_by_key(|(i, _, _)| *i);
    let mut summary = Vec::new();
    for (_, target, result) in results {
        summary.push((target, result?));
    }
    println!(
        "\n| target | executions | coverage (edges) | features | corpus |\n|---|---|---|---|---|"
    );
    for (target, s) in summary {
        println!(
            "| {target} | {} | {} | {} | {} |",
            s.runs, s.cov, s.ft, s.corpus
        );
    }
    Ok(())
}

/// One target's run from its corpus directory `dir`: its statistics, or
/// the failure with the tail of libFuzzer's log.
fn run_target(root: &Path, target: &str, dir: &Path, seconds: u64) -> Result<Stats, String> {
    let out = Command::new("cargo")
        .current_dir(root.join("fuzz"))
        .args(["+nightly", "fuzz", "run", target])
        .arg(dir)
        .args([
            "--",
            &format!("-max_total_time={seconds}"),
            "-rss_limit_mb=2048",
            "-print_final_stats=1",
        ])
        .output()
        .map_err(|e| format!("cannot run cargo fuzz: {e}"))?;
    let log = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        let tail: Vec<&str> = log.lines().rev().take(40).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        return Err(format!(
            "fuzz target {target} found a failure (the input is under fuzz/artifacts/{target}/; \
             fix it, then add the input to fuzz/regressions/{target}/):\n{}",
            tail.join("\n")
        ));
    }
    Ok(stats(&log))
}

/// nightly (for `-Zsanitizer`) and cargo-fuzz, installed if missing.
fn ensure_tools() -> Result<(), String> {
    let listed = Command::new("rustup")
        .args(["toolchain", "list"])
        .output()
        .map_err(|e| format!("cannot run rustup: {e}"))?;
    if !String::from_utf8_lossy(&listed.stdout).contains("nightly") {
        crate::run(
            "rustup",
            &["toolchain", "install", "nightly", "--profile", "minimal"],
        )?;
    }
    let has_fuzz = Command::new("cargo")
        .args(["fuzz", "--version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_fuzz {
        crate::run("cargo", &["install", "cargo-fuzz", "--locked"])?;
    }
    Ok(())
}

#[derive(Default)]
struct Stats {
    runs: String,
    cov: String,
    ft: String,
    corpus: String,
}

/// From libFuzzer's final statistics (`stat::number_of_executed_units`)
/// and its last status line (`#N ... cov: C ft: F corp: K/S ...`).
fn stats(log: &str) -> Stats {
    let runs = log
        .lines()
        .find_map(|l| l.strip_prefix("stat::number_of_executed_units:"))
        .map_or(String::from("?"), |n| n.trim().to_string());
    let status = log
        .lines()
        .rev()
        .find(|l| l.starts_with('#') && l.contains("cov:"))
        .unwrap_or_default();
    let words: Vec<&str> = status.split_whitespace().collect();
    let after = |key: &str| {
        words
            .iter()
            .position(|w| *w == key)
            .and_then(|i| words.get(i + 1))
            .map_or(String::from("?"), |w| w.to_string())
    };
    Stats {
        runs,
        cov: after("cov:"),
        ft: after("ft:"),
        corpus: after("corp:"),
    }
}

/// A seed: the target it is for, a file name and its bytes.
type Seed = (&'static str, String, Vec<u8>);

/// Every target's seeds.
fn seeds(root: &Path) -> Result<Vec<Seed>, String> {
    let models = root.join("models");
    let read = |p: PathBuf| std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()));
    let shipped_int8 = read(models.join("embedded-default-int8.pcrn"))?;
    let shipped_f32 = read(models.join("embedded-default-f32.pcrn"))?;
    let source = read(models.join("embedded-default-source.f32"))?;
    let cloud: Vec<[f32; 3]> = source
        .chunks_exact(12)
        .take(64)
        .map(|c| [0, 4, 8].map(|i| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]])))
        .collect();
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    let small_int8 = random_int8_blob_into(1, &[8, 16], &[16], &mut arena, &mut out)
        .map_err(|e| format!("{e:?}"))?
        .to_vec();
    let small_f32 = random_f32_blob_into(2, &[8, 16], &[16], &mut arena, &mut out)
        .map_err(|e| format!("{e:?}"))?
        .to_vec();
    let mut s = Vec::new();
    for (name, blob) in [
        ("small-int8", &small_int8),
        ("small-f32", &small_f32),
        ("shipped-int8", &shipped_int8),
        ("shipped-f32", &shipped_f32),
    ] {
        s.push(("blob", name.to_string(), blob.clone()));
        // The first byte: the kind, and how many formats back the blob's
        // own is (`pcrnet_fuzz::version_of`), so the seed decodes.
        let kind = u8::from(name.ends_with("f32"));
        let version = u16::from_le_bytes([blob[4], blob[5]]);
        let back = u8::try_from(FORMAT_VERSION - version).map_err(|e| e.to_string())?;
        let payload = &blob[HEADER_LEN..blob.len() - CRC_LEN];
        s.push((
            "blob_sealed",
            name.to_string(),
            [&[kind | back << 1], payload].concat(),
        ));
    }
    let cloud_bytes: Vec<u8> = cloud
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let options = [1u8; 16];
    s.push((
        "cloud",
        "demo-64".into(),
        [&options[..], &cloud_bytes].concat(),
    ));
    let mut capi = [0u8; 20];
    capi[..2].copy_from_slice(&(small_int8.len() as u16).to_le_bytes());
    capi[2] = 1;
    s.push((
        "capi",
        "small-int8-demo-64".into(),
        [&capi[..], &small_int8, &cloud_bytes].concat(),
    ));
    for (name, bytes) in files(&cloud) {
        let target = match name.split('.').next_back() {
            Some("pcd") => "read_pcd",
            Some("ply") => "read_ply",
            Some("off") => "read_off",
            _ => "read_xyz",
        };
        s.push((target, name, bytes));
    }
    Ok(s)
}

/// The cloud in every layout the readers take.
fn files(cloud: &[[f32; 3]]) -> Vec<(String, Vec<u8>)> {
    let n = cloud.len();
    let text: String = cloud
        .iter()
        .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    let le: Vec<u8> = cloud
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let be: Vec<u8> = cloud
        .iter()
        .flatten()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    // Struct of arrays, then LZF of literal runs (at most 32 bytes each).
    let soa: Vec<u8> = (0..3)
        .flat_map(|k| cloud.iter().flat_map(move |p| p[k].to_le_bytes()))
        .collect();
    let mut lzf = Vec::new();
    for run in soa.chunks(32) {
        lzf.push((run.len() - 1) as u8);
        lzf.extend_from_slice(run);
    }
    let pcd = |data: &str| {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
        )
    };
    let ply = |format: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
        )
    };
    let compressed = [
        (lzf.len() as u32).to_le_bytes(),
        (soa.len() as u32).to_le_bytes(),
    ]
    .concat();
    let faces: String = (0..n.saturating_sub(2))
        .map(|i| format!("3 {} {} {}\n", i, i + 1, i + 2))
        .collect();
    vec![
        (
            "ascii.pcd".into(),
            [pcd("ascii").as_bytes(), text.as_bytes()].concat(),
        ),
        (
            "binary.pcd".into(),
            [pcd("binary").as_bytes(), &le].concat(),
        ),
        (
            "compressed.pcd".into(),
            [pcd("binary_compressed").as_bytes(), &compressed, &lzf].concat(),
        ),
        (
            "ascii.ply".into(),
            [ply("ascii").as_bytes(), text.as_bytes()].concat(),
        ),
        (
            "le.ply".into(),
            [ply("binary_little_endian").as_bytes(), &le].concat(),
        ),
        (
            "be.ply".into(),
            [ply("binary_big_endian").as_bytes(), &be].concat(),
        ),
        (
            "mesh.off".into(),
            format!("OFF\n{n} {} 0\n{text}{faces}", n.saturating_sub(2)).into_bytes(),
        ),
        (
            "points.off".into(),
            format!("OFF\n{n} 0 0\n{text}").into_bytes(),
        ),
        ("points.xyz".into(), text.into_bytes()),
    ]
}
