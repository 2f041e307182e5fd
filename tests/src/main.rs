//! `qemu-harness`: runs `pcrnet-core` on an emulated Cortex-M4F and checks
//! it agrees with the host bit for bit.
//!
//! ```text
//! qemu-harness run [--mutate-device-rounding] [--timeout SECS]
//! qemu-harness size
//! ```
//! `run` ends with `N passed, N failed`. With `--mutate-device-rounding`
//! the device is built with ties rounded the other way, and the command
//! succeeds only if the comparison catches it.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use pcrnet_core::{Int8Model, MAX_TILE};
use pcrnet_qemu_tests::compare::{first_difference, iterative_difference, parse};
use pcrnet_qemu_tests::vectors::{
    Case, TestModel, clouds_for, container, expected, expected_iterative, random_model,
};
use pcrnet_qemu_tests::{elf, qemu};

/// Random models covering the shapes' corners, every int8 blob shipped in
/// `models/`, and the paper-size PCRNet (its 4.2 MB of weights go to PSRAM).
fn models() -> anyhow::Result<Vec<(TestModel, Vec<usize>)>> {
    let mut out = vec![
        (
            random_model("random 16-24-64 / 48-32", 1, &[16, 24, 64], &[48, 32]),
            vec![1, 2, 3, 7, 8, 9, 16, 31, 257, 1024, 3000],
        ),
        (
            random_model("random 8 / - (one layer each)", 2, &[8], &[]),
            vec![1, 5, 100],
        ),
        (
            random_model(
                "random 8+8 layers",
                3,
                &[24, 24, 24, 24, 24, 24, 24, 96],
                &[64; 8],
            ),
            vec![1, 33, 500],
        ),
    ];
    let dir = qemu::workspace_root().join("models");
    let mut shipped: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with("-int8.pcrn"))
        .collect();
    shipped.sort();
    for path in shipped {
        let blob = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        let name = path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        out.push((TestModel { name, blob }, vec![1, 100, 1024, 4096]));
    }
    out.push((
        random_model(
            "paper PCRNet 64-64-64-128-1024 / 1024-1024-512-512-256 (PSRAM)",
            4,
            pcrnet_core::arch::PAPER_ENCODER,
            pcrnet_core::arch::PCRNET_HEAD,
        ),
        vec![1, 9, 1024],
    ));
    Ok(out)
}

fn build_cases(models: &[(TestModel, Vec<usize>)]) -> (Vec<TestModel>, Vec<Case>) {
    let mut cases = Vec::new();
    let mut out = Vec::new();
    for (mi, (model, sizes)) in models.iter().enumerate() {
        for (label, cloud) in clouds_for(&model.blob, 100 + mi as u64, sizes) {
            // Vary the tile; the measured 1024-point cases use the largest.
            let tile = if cloud.len() == 1024 {
                MAX_TILE
            } else {
                cases.len() % MAX_TILE + 1
            };
            // i-PCRNet passes on the small clouds and every invalid one.
            let iterations = if cloud.len() <= 300 { 3 } else { 0 };
            cases.push(Case {
                model: mi,
                label,
                cloud,
                tile,
                iterations,
            });
        }
        out.push(TestModel {
            name: model.name.clone(),
            blob: model.blob.clone(),
        });
    }
    (out, cases)
}

struct Args {
    mutate: bool,
    timeout: Duration,
}

fn run(args: Args) -> anyhow::Result<bool> {
    let root = qemu::workspace_root();
    let (models, cases) = build_cases(&models()?);
    let expect: Vec<_> = cases
        .iter()
        .map(|c| {
            let blob = &models[c.model].blob;
            (expected(blob, c), expected_iterative(blob, c))
        })
        .collect();
    let dir = root.join("target/qemu");
    std::fs::create_dir_all(&dir)?;
    let vectors = dir.join("vectors.bin");
    std::fs::write(&vectors, container(&models, &cases)?)?;

    let features: &[&str] = if args.mutate {
        &["mutate-rounding"]
    } else {
        &[]
    };
    let elf = qemu::build_firmware(&root.join("tests/firmware"), "pcrnet-qemu-runner", features)?;
    println!(
        "running {} cases on {} models under QEMU (mps2-an386)...",
        cases.len(),
        models.len()
    );
    let stdout = qemu::run_with_timeout(qemu::qemu_command(&elf, Some(&vectors)), args.timeout)?;
    std::fs::write(dir.join("device-output.txt"), &stdout)?;
    let device = parse(&stdout);

    let (mut passed, mut failed) = (0usize, 0usize);
    for (i, (case, (host, host_iterative))) in cases.iter().zip(&expect).enumerate() {
        let verdict = match device.cases.get(&i) {
            None => Some("no output from the device".to_string()),
            Some(d) => first_difference(host, &d.outputs),
        }
        .or_else(|| {
            host_iterative
                .as_ref()
                .and_then(|h| iterative_difference(h, device.iterative.get(&i)))
        });
        match verdict {
            None => passed += 1,
            Some(why) => {
                failed += 1;
                if !args.mutate || failed <= 3 {
                    println!(
                        "FAIL case {i} ({}, {}, {} points, tile {}): {why}",
                        models[case.model].name,
                        case.label,
                        case.cloud.len(),
                        case.tile
                    );
                }
            }
        }
    }
    for line in &device.unparsed {
        println!("unparsed device output: {line}");
    }
    let complete = device.done && device.unparsed.is_empty();

    if args.mutate {
        println!(
            "mutation check: with device rounding changed, {failed} of {} cases differ from the host (they must)",
            cases.len()
        );
        return Ok(failed > 0);
    }

    report(&models, &cases, &device, &elf)?;
    if !complete {
        println!("device run incomplete (no `done`, or unparsed lines)");
    }
    println!("{passed} passed, {failed} failed");
    Ok(failed == 0 && complete)
}

fn report(
    models: &[TestModel],
    cases: &[Case],
    device: &pcrnet_qemu_tests::compare::DeviceRun,
    elf: &std::path::Path,
) -> anyhow::Result<()> {
    if let Some((want, got)) = device.calibration {
        println!("instruction counter calibration: {got} counted for {want} executed");
    }
    let sizes = elf::sizes(elf)?;
    println!(
        "runner image: flash {} B (text {} + rodata {} + data {}), static RAM {} B (of which 65,536 scratch)",
        sizes.flash(),
        sizes.text,
        sizes.rodata,
        sizes.data,
        sizes.static_ram()
    );
    println!(
        "\n| model | blob B | points | instructions / inference | encoder instr/MAC | head instr/MAC | peak stack B |\n|---|---|---|---|---|---|---|"
    );
    for (mi, model) in models.iter().enumerate() {
        let m = Int8Model::from_bytes(&model.blob)?;
        let arch = m.arch();
        let stack = cases
            .iter()
            .enumerate()
            .filter(|(_, c)| c.model == mi)
            .filter_map(|(i, _)| device.cases.get(&i))
            .map(|d| d.stack)
            .max()
            .unwrap_or(0);
        let measured = cases
            .iter()
            .enumerate()
            .filter(|(i, c)| {
                c.model == mi
                    && c.tile == MAX_TILE
                    && device
                        .cases
                        .get(i)
                        .is_some_and(|d| d.infer_instructions > 0)
            })
            .max_by_key(|(_, c)| c.cloud.len());
        if let Some((i, c)) = measured {
            let d = &device.cases[&i];
            let enc_macs = (c.cloud.len() * arch.encoder_macs_per_point()) as f64;
            let head_instr = d.infer_instructions.saturating_sub(d.encode_instructions) as f64;
            println!(
                "| {} | {} | {} | {} | {:.2} | {:.2} | {} |",
                model.name,
                model.blob.len(),
                c.cloud.len(),
                d.infer_instructions,
                d.encode_instructions as f64 / enc_macs,
                head_instr / arch.head_macs() as f64,
                stack
            );
        }
    }
    println!();
    Ok(())
}

fn size() -> anyhow::Result<()> {
    let root = qemu::workspace_root();
    let elf = qemu::build_firmware(
        &root.join("firmware-example"),
        "pcrnet-firmware-example",
        &[],
    )?;
    let s = elf::sizes(&elf)?;
    println!(
        "firmware-example: flash {} B (text {} + rodata {} incl. model + data {}), static RAM {} B (data {} + bss {})",
        s.flash(),
        s.text,
        s.rodata,
        s.data,
        s.static_ram(),
        s.data,
        s.bss
    );
    Ok(())
}

fn parse_args() -> anyhow::Result<(String, Args)> {
    let mut it = std::env::args().skip(1);
    let command = it.next().unwrap_or_else(|| "run".into());
    let mut args = Args {
        mutate: false,
        timeout: Duration::from_secs(1200),
    };
    while let Some(a) = it.next() {
        match a.as_str() {
            "--mutate-device-rounding" => args.mutate = true,
            "--timeout" => {
                let secs: u64 = it.next().context("--timeout needs seconds")?.parse()?;
                args.timeout = Duration::from_secs(secs);
            }
            other => anyhow::bail!("unknown argument {other}"),
        }
    }
    Ok((command, args))
}

fn main() -> ExitCode {
    let result = parse_args().and_then(|(command, args)| match command.as_str() {
        "run" => run(args),
        "size" => size().map(|()| true),
        other => anyhow::bail!("unknown command {other} (run | size)"),
    });
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("qemu-harness: {e:#}");
            ExitCode::FAILURE
        }
    }
}
