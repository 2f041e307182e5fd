//! The figures CI's log carries on their own lines, from the device's
//! instruction counts: the shipped model's default registration and
//! tracking step with its latency table, the feature-space check and the
//! scene path ([`report`]), and PointNetLK's registration and step.

use crate::compare::DeviceRun;
use crate::plan::{NOISY, SHIPPED_LK, every_point, lk_only};
use crate::vectors::{Case, TestModel};

/// Prints every figure whose cases ran (a figure whose registration did
/// not is left out).
pub fn report(models: &[TestModel], cases: &[Case], device: &DeviceRun) {
    shipped(models, cases, device);
    lk(models, cases, device);
}

/// PointNetLK's figures for CI's log, on their own lines: on the shipped
/// model's encoder with a random solver ([`SHIPPED_LK`]; no PointNetLK
/// model is shipped; a step's cost hardly depends on the solver's values), one
/// registration by LK alone of the 512-point demo source, 5 steps, and one
/// step's cost, `(5 steps - 1 step) / 4`.
fn lk(models: &[TestModel], cases: &[Case], device: &DeviceRun) {
    let demo = cases.iter().enumerate().find(|(_, c)| {
        models[c.model].name == SHIPPED_LK && c.label.starts_with("demo") && c.cloud.len() == 512
    });
    let Some((i, c)) = demo else {
        return;
    };
    let instructions = |steps: usize| {
        let k = c.registrations.iter().position(|o| *o == lk_only(steps))?;
        let d = device.registrations.get(&(i, k))?;
        d.outcome.is_ok().then_some(d.instructions)
    };
    let (Some(five), Some(one)) = (instructions(5), instructions(1)) else {
        return;
    };
    println!(
        "PointNetLK registration (LK only, 5 steps; shipped encoder, random solver), 512 points: {five} instructions"
    );
    println!(
        "PointNetLK step ((5 steps - 1 step) / 4; shipped encoder, random solver), 512 points: {} instructions",
        five.saturating_sub(one) / 4
    );
}

/// The two figures CI's log carries, on their own lines: the shipped
/// model's default registration of its 512-point demo source, and a
/// tracking step on it from the registered pose (the pose held; 256 of the
/// 512 points scored and refined, `Options::default().max_points`); then
/// the latency table of the shipped model's demo sources (256, 512 and
/// 1,024 points).
fn shipped(models: &[TestModel], cases: &[Case], device: &DeviceRun) {
    let default = pcrnet_core::Options::default();
    let demo = |n: usize| {
        cases.iter().enumerate().find(|(_, c)| {
            models[c.model].name == "embedded-default-int8.pcrn"
                && c.label.starts_with("demo")
                && c.cloud.len() == n
        })
    };
    // (instructions of: network only, K = 1, default, tracking step held)
    let figures = |n: usize| -> Option<[u64; 4]> {
        let (i, c) = demo(n)?;
        let at = |o: &pcrnet_core::Options| c.registrations.iter().position(|r| r == o);
        let k1 = pcrnet_core::Options {
            hypotheses: 1,
            ..default
        };
        let reg =
            |o: &pcrnet_core::Options| Some(device.registrations.get(&(i, at(o)?))?.instructions);
        let track = device
            .tracks
            .get(&(i, at(&default)?, "held".to_string()))?
            .instructions;
        Some([
            reg(&pcrnet_core::Options::network_only())?,
            reg(&k1)?,
            reg(&default)?,
            track,
        ])
    };
    if let Some([_, _, registration, track]) = figures(512) {
        println!("default registration, 512 points: {registration} instructions");
        println!("tracking step, 256 points: {track} instructions");
    }
    let dense_step = demo(512).and_then(|(i, c)| {
        let k = c.registrations.iter().position(|r| *r == every_point())?;
        Some(device.tracks.get(&(i, k, "held".to_string()))?.instructions)
    });
    if let Some(step) = dense_step {
        println!("tracking step, 512 scored points: {step} instructions");
    }
    let noisy = cases.iter().enumerate().find_map(|(i, c)| {
        let shipped = models[c.model].name == "embedded-default-int8.pcrn";
        let k = c.registrations.iter().position(|r| *r == default)?;
        (shipped && c.label.starts_with(NOISY))
            .then(|| device.registrations.get(&(i, k)))
            .flatten()
    });
    if let Some(d) = noisy {
        println!(
            "default registration, 512 points with noise (sigma 0.01): {} instructions",
            d.instructions
        );
    }
    let check = demo(512).and_then(|(i, c)| {
        let k = c.registrations.iter().position(|r| *r == default)?;
        Some(device.features.get(&(i, k))?.instructions)
    });
    if let Some(check) = check {
        println!(
            "feature-space check (Int8Model::feature_distance), 512 points: {check} instructions"
        );
    }
    let viewed_step = demo(512).and_then(|(i, c)| {
        let k = c.registrations.iter().position(|r| *r == default)?;
        let d = device.tracks.get(&(i, k, "viewed-held".to_string()))?;
        Some((d.instructions, d.stack))
    });
    if let Some((step, stack)) = viewed_step {
        println!(
            "tracking step of a view (Int8Model::track_view, the pose held, the view rendered), 512 points: {step} instructions, peak stack {stack} B"
        );
    }
    let view = demo(512).and_then(|(i, c)| {
        let k = c.registrations.iter().position(|r| *r == default)?;
        let d = device.views.get(&(i, k))?;
        Some((d.instructions, d.stack))
    });
    if let Some((view, stack)) = view {
        println!(
            "registration seen from a viewpoint (Int8Model::register_view), 512 points: {view} instructions, peak stack {stack} B"
        );
    }
    let shipped = models
        .iter()
        .position(|m| m.name == "embedded-default-int8.pcrn");
    if let Some(s) = shipped.and_then(|m| device.scenes.get(&m)) {
        let (w, h) = (
            pcrnet_core::testing::scene::HARNESS_WIDTH,
            pcrnet_core::testing::scene::HARNESS_HEIGHT,
        );
        if let Some(segment) = s.segment {
            println!("scene stages, {w} x {h} frame: {segment} instructions");
        }
        for (name, how) in [
            ("locate", "the network's hypotheses"),
            ("sweep", "the yaw sweep, --up given"),
        ] {
            if let Some(run) = s.runs.get(name) {
                println!(
                    "locate ({how}; scene stages, {} candidates registered and verified), {w} x {h} frame: {} instructions, peak stack {} B",
                    run.result
                        .as_ref()
                        .map_or(0, |words| words.matches(" t ").count()),
                    run.instructions,
                    run.stack
                );
            }
        }
        if let Some(run) = s.runs.get("follow") {
            println!(
                "follow (the next frame from the last pose and plane: the box about the object, ICP, verified), {w} x {h} frame: {} instructions, peak stack {} B",
                run.instructions, run.stack
            );
        }
    }
    println!(
        "\nlatency of the shipped model on its demo source (instructions, and ms at 168 MHz (M4) / 480 MHz (M7) \
         assuming one cycle per instruction: flash wait states make the M4 slower, dual issue the M7 faster)\n\
         | points | network only | K = 1 | default (K = 10) | tracking step (pose held) |\n|---|---|---|---|---|"
    );
    for n in [256, 512, 1024] {
        let Some(f) = figures(n) else {
            continue;
        };
        let cell = |v: u64| {
            format!(
                "{:.1} M ({:.0} / {:.0} ms)",
                v as f64 / 1e6,
                v as f64 / 168e3,
                v as f64 / 480e3
            )
        };
        println!(
            "| {n} | {} | {} | {} | {} |",
            cell(f[0]),
            cell(f[1]),
            cell(f[2]),
            cell(f[3])
        );
    }
    println!();
}
