//! `qemu-harness`: runs `pcrnet-core` on an emulated Cortex-M4F and checks
//! it agrees with the host bit for bit.
//!
//! ```text
//! qemu-harness run [--board MACHINE] [--mutate-device-rounding] [--timeout SECS]
//! qemu-harness layers [--board MACHINE]
//! qemu-harness size
//! qemu-harness c-example
//! ```
//! Every case compares the inference (int8 feature, head, pose), and as
//! the case asks, the iterative network pass and `Int8Model::register`
//! with its option sets (every `Registration` field bit for bit, or the
//! same error; PointNetLK's steps on the blobs with a solver), then
//! `Int8Model::track` after each registration (see `tracking`). `run` ends
//! with `N passed, N failed`. With `--mutate-device-rounding` the device is
//! built with ties rounded the other way, and the command succeeds only if
//! the comparison catches it, in the inference, in the registrations and
//! in the PointNetLK registrations among them.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use pcrnet_core::{Int8Model, MAX_TILE};
use pcrnet_qemu_tests::compare::{
    DeviceRun, first_difference, iterative_difference, parse, registration_difference,
};
use pcrnet_qemu_tests::hostile::load_verdict;
use pcrnet_qemu_tests::plan::{NOISY, Plan, build_cases, models};
use pcrnet_qemu_tests::vectors::{
    Case, TestModel, container, describe, expected, expected_iterative, expected_registrations,
};
use pcrnet_qemu_tests::{c_example, elf, feature, figures, layers, qemu, scene, tracking, view};

struct Args {
    mutate: bool,
    timeout: Duration,
    board: &'static qemu::Board,
}

fn run(args: Args) -> anyhow::Result<bool> {
    let plans = models(args.board.cases)?;
    Ok(run_plans(&args, &plans, false)?.0)
}

/// Per-layer instructions per MAC (see `layers`): the prefix models, each
/// on one 1,024-point cloud (and the few invalid clouds every model gets),
/// in batches that fit the data region, checked bit for bit like every run.
fn run_layers(args: Args) -> anyhow::Result<bool> {
    let prefixes = layers::prefixes();
    let mut measurements = Vec::new();
    let mut ok = true;
    for batch in layers::batches(&prefixes) {
        let plans: Vec<Plan> = prefixes[batch]
            .iter()
            .map(|p| Plan {
                model: TestModel {
                    name: p.model.name.clone(),
                    blob: p.model.blob.clone(),
                },
                sizes: vec![layers::POINTS],
                sources: Vec::new(),
                options: Vec::new(),
            })
            .collect();
        let (passed, mut m) = run_plans(&args, &plans, true)?;
        ok &= passed;
        measurements.append(&mut m);
    }
    layers::report(&prefixes, &measurements)?;
    Ok(ok)
}

/// Runs `plans` on the device and compares; prints the usual report unless
/// `quiet`. Returns whether everything agreed, and each model's `(encode,
/// infer)` instructions on its 1,024-point uniform cloud.
fn run_plans(
    args: &Args,
    plans: &[Plan],
    quiet: bool,
) -> anyhow::Result<(bool, Vec<layers::Measurement>)> {
    let root = qemu::workspace_root();
    let board = args.board;
    let (models, cases) = build_cases(plans);
    let expect: Vec<_> = cases
        .iter()
        .map(|c| {
            let blob = &models[c.model].blob;
            let registrations = expected_registrations(blob, c);
            let tracks = tracking::expected(blob, c, &registrations, view::side_for(board.machine));
            let features = feature::expected(blob, c, &registrations);
            let views = view::expected(blob, c, &registrations, view::side_for(board.machine));
            (
                expected(blob, c),
                expected_iterative(blob, c),
                registrations,
                (tracks, features, views),
            )
        })
        .collect();
    // The scene path per int8 model (not on the micro:bit: see `scene`).
    let host_scenes: Vec<Option<Vec<scene::SceneResult>>> = if board.machine == "microbit" {
        vec![None; models.len()]
    } else {
        models.iter().map(|m| scene::expected(&m.blob)).collect()
    };
    let dir = root.join("target/qemu");
    std::fs::create_dir_all(&dir)?;
    // One file per run: two runs at once (say `cargo xtask cores` beside
    // `qemu-test`) must not load each other's cases, which fails every
    // case after the first difference with outputs off by one.
    let vectors = dir.join(format!(
        "vectors-{}-{}.bin",
        board.machine,
        std::process::id()
    ));
    std::fs::write(&vectors, container(&models, &cases, board.data_len)?)?;

    let features: &[&str] = if args.mutate {
        &["mutate-rounding"]
    } else {
        &[]
    };
    let elf = qemu::build_firmware(
        &root.join("tests/firmware"),
        "pcrnet-qemu-runner",
        board,
        features,
    )?;
    println!(
        "running {} cases ({} registrations) on {} models under QEMU ({}, {}, {} kernel)...",
        cases.len(),
        cases.iter().map(|c| c.registrations.len()).sum::<usize>(),
        models.len(),
        board.machine,
        board.core,
        board.kernel
    );
    let started = std::time::Instant::now();
    let stdout = qemu::run_with_timeout(
        qemu::qemu_command(board, &elf, Some(&vectors)),
        args.timeout,
    )?;
    // Gone with the run (a leftover is only disk space).
    let _ = std::fs::remove_file(&vectors);
    println!("QEMU ran for {:.1} s", started.elapsed().as_secs_f64());
    std::fs::write(
        dir.join(format!("device-output-{}.txt", board.machine)),
        &stdout,
    )?;
    let device = parse(&stdout);

    let (mut passed, mut failed) = (0usize, 0usize);
    let (mut registrations, mut registrations_differ) = (0usize, 0usize);
    // Those that ran PointNetLK's steps on the host.
    let (mut lk_registrations, mut lk_differ) = (0usize, 0usize);
    let (mut tracks, mut tracks_differ) = (0usize, 0usize);
    let (mut features, mut features_differ) = (0usize, 0usize);
    let (mut views, mut views_differ) = (0usize, 0usize);
    for (
        i,
        (
            case,
            (host, host_iterative, host_registrations, (host_tracks, host_features, host_views)),
        ),
    ) in cases.iter().zip(&expect).enumerate()
    {
        let view_verdicts: Vec<String> = host_views
            .iter()
            .filter_map(|(k, h)| {
                let d = device.views.get(&(i, *k)).map(|d| &d.result);
                view::difference(h, d).map(|why| format!("view check #{k}: {why}"))
            })
            .collect();
        views += host_views.len();
        views_differ += view_verdicts.len();
        let feature_verdicts: Vec<String> = host_features
            .iter()
            .filter_map(|(k, h)| {
                let d = device.features.get(&(i, *k)).map(|d| &d.result);
                feature::difference(h, d).map(|why| format!("feature check #{k}: {why}"))
            })
            .collect();
        features += host_features.len();
        features_differ += feature_verdicts.len();
        let track_verdicts: Vec<String> = host_tracks
            .iter()
            .filter_map(|((k, start), h)| {
                let d = device
                    .tracks
                    .get(&(i, *k, start.clone()))
                    .map(|d| &d.result);
                tracking::difference(h, d).map(|why| format!("track #{k} from {start}: {why}"))
            })
            .collect();
        tracks += host_tracks.len();
        tracks_differ += track_verdicts.len();
        let register_verdicts: Vec<Option<String>> = host_registrations
            .iter()
            .zip(&case.registrations)
            .enumerate()
            .map(|(k, (h, options))| {
                let d = device.registrations.get(&(i, k)).map(|d| &d.outcome);
                registration_difference(h, d)
                    .map(|why| format!("register #{k} ({}): {why}", describe(options)))
            })
            .collect();
        registrations += register_verdicts.len();
        registrations_differ += register_verdicts.iter().flatten().count();
        for (h, verdict) in host_registrations.iter().zip(&register_verdicts) {
            if h.as_ref().is_ok_and(|r| r.lk_iterations > 0) {
                lk_registrations += 1;
                lk_differ += usize::from(verdict.is_some());
            }
        }
        let verdict = match device.cases.get(&i) {
            None => Some("no output from the device".to_string()),
            Some(d) => first_difference(host, &d.outputs),
        }
        .or_else(|| {
            host_iterative
                .as_ref()
                .and_then(|h| iterative_difference(h, device.iterative.get(&i)))
        })
        .or_else(|| register_verdicts.into_iter().flatten().next())
        .or_else(|| track_verdicts.into_iter().next())
        .or_else(|| feature_verdicts.into_iter().next())
        .or_else(|| view_verdicts.into_iter().next());
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
    // Every model's load verdict, the hostile blobs' above all.
    for (m, model) in models.iter().enumerate() {
        let host = load_verdict(&model.blob);
        let on_device = device.loads.get(&m);
        if on_device != Some(&host) {
            failed += 1;
            println!(
                "FAIL model {m} ({}): load: host `{host}`, device `{}`",
                model.name,
                on_device.map_or("nothing", String::as_str)
            );
        } else if model.name.starts_with("f32 head") {
            println!("model {m} ({}): refused alike: {host}", model.name);
        }
    }
    let (mut scenes, mut scenes_differ) = (0usize, 0usize);
    for (m, host) in host_scenes.iter().enumerate() {
        let Some(host) = host else {
            continue;
        };
        scenes += 1;
        if let Some(why) = scene::difference(host, device.scenes.get(&m)) {
            scenes_differ += 1;
            failed += 1;
            if !args.mutate || scenes_differ <= 2 {
                println!("FAIL model {m} ({}) scene: {why}", models[m].name);
            }
        }
    }
    for line in &device.unparsed {
        println!("unparsed device output: {line}");
    }
    let complete = device.done && device.unparsed.is_empty();

    if args.mutate {
        println!(
            "mutation check: with device rounding changed, {failed} of {} cases and scenes differ from the host, \
             {registrations_differ} of {registrations} registrations ({lk_differ} of {lk_registrations} with PointNetLK steps) \
             and {scenes_differ} of {scenes} scenes (they must)",
            cases.len() + scenes
        );
        return Ok((
            failed > 0 && registrations_differ > 0 && lk_differ > 0,
            Vec::new(),
        ));
    }

    let measurements = (0..models.len())
        .map(|m| layers::measured(&cases, &device, m))
        .collect();
    if !quiet {
        report(&models, &cases, &device, &elf)?;
    }
    if !complete {
        println!("device run incomplete (no `done`, or unparsed lines)");
    }
    println!(
        "{registrations} registrations, {} identical; {tracks} tracking steps, {} identical; {features} feature checks, {} identical; {views} viewed registrations, {} identical; {scenes} scenes, {} identical",
        registrations - registrations_differ,
        tracks - tracks_differ,
        features - features_differ,
        views - views_differ,
        scenes - scenes_differ
    );
    println!(
        "{} ({}): {passed} passed, {failed} failed",
        board.machine, board.core
    );
    Ok((failed == 0 && complete, measurements))
}

fn report(
    models: &[TestModel],
    cases: &[Case],
    device: &DeviceRun,
    elf: &std::path::Path,
) -> anyhow::Result<()> {
    if let Some((want, got)) = device.calibration {
        println!("instruction counter calibration: {got} counted for {want} executed");
    }
    let sizes = elf::sizes(elf)?;
    println!(
        "runner image: flash {} B (text {} + rodata {} + data {}), static RAM {} B (the scratch included)",
        sizes.flash(),
        sizes.text,
        sizes.rodata,
        sizes.data,
        sizes.static_ram()
    );
    println!(
        "\n| model | blob B | points | instructions / inference | encoder instr/MAC | head instr/MAC | peak stack B | load stack B |\n|---|---|---|---|---|---|---|---|"
    );
    for (mi, model) in models.iter().enumerate() {
        // The hostile blobs (no cases) do not load.
        let Ok(m) = Int8Model::from_bytes(&model.blob) else {
            continue;
        };
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
                    && c.cloud.len() == 1024
                    && c.label.starts_with("uniform")
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
                "| {} | {} | {} | {} | {:.2} | {:.2} | {} | {} |",
                model.name,
                model.blob.len(),
                c.cloud.len(),
                d.infer_instructions,
                d.encode_instructions as f64 / enc_macs,
                head_instr / arch.head_macs() as f64,
                stack,
                device
                    .load_stacks
                    .get(&mi)
                    .map_or("-".to_string(), |s| s.to_string())
            );
        }
    }
    println!();
    report_registrations(models, cases, device);
    figures::report(models, cases, device);
    Ok(())
}

/// Instructions and stack per `register` call: every option set on each
/// model's largest uniform cloud that registers and on its realistic sources.
fn report_registrations(models: &[TestModel], cases: &[Case], device: &DeviceRun) {
    println!(
        "| model | source | points | options | instructions / registration | ICP iterations | hypothesis | reliable | peak stack B |\n|---|---|---|---|---|---|---|---|---|"
    );
    for (mi, model) in models.iter().enumerate() {
        let ok = |i: usize, c: &Case| {
            c.model == mi
                && !c.registrations.is_empty()
                && device
                    .registrations
                    .get(&(i, 0))
                    .is_some_and(|d| d.outcome.is_ok())
        };
        let largest_uniform = cases
            .iter()
            .enumerate()
            .filter(|&(i, c)| ok(i, c) && c.label.starts_with("uniform"))
            .max_by_key(|(_, c)| c.cloud.len())
            .map(|(i, _)| i);
        let shown = cases.iter().enumerate().filter(|&(i, c)| {
            ok(i, c)
                && (c.label.starts_with("demo")
                    || c.label.starts_with(NOISY)
                    || Some(i) == largest_uniform)
        });
        for (i, c) in shown {
            for (k, options) in c.registrations.iter().enumerate() {
                let Some(d) = device.registrations.get(&(i, k)) else {
                    continue;
                };
                let Ok(r) = &d.outcome else {
                    continue;
                };
                println!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                    model.name,
                    c.label,
                    c.cloud.len(),
                    describe(options),
                    d.instructions,
                    r.icp_iterations,
                    r.hypothesis,
                    r.reliable,
                    d.stack
                );
            }
        }
    }
    let deepest = device.registrations.iter().max_by_key(|(_, d)| d.stack);
    if let Some((&(i, k), d)) = deepest {
        let c = &cases[i];
        println!(
            "\npeak stack of register over {} calls: {} B ({}, {}, {} points, {})",
            device.registrations.len(),
            d.stack,
            models[c.model].name,
            c.label,
            c.cloud.len(),
            c.registrations.get(k).map(describe).unwrap_or_default()
        );
    }
    println!();
}

fn size() -> anyhow::Result<()> {
    let root = qemu::workspace_root();
    let elf = qemu::build_firmware(
        &root.join("firmware-example"),
        "pcrnet-firmware-example",
        &qemu::BOARDS[0],
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
        board: &qemu::BOARDS[0],
    };
    while let Some(a) = it.next() {
        match a.as_str() {
            "--mutate-device-rounding" => args.mutate = true,
            "--board" => {
                args.board = qemu::board(&it.next().context("--board needs a QEMU machine")?)?
            }
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
        "layers" => run_layers(args),
        "c-example" => c_example::run(args.timeout).map(|()| true),
        other => anyhow::bail!("unknown command {other} (run | layers | size | c-example)"),
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
