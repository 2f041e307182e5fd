//! The paper's timing and convergence experiments: `speed` (its Table 1,
//! with the int8 / f32 precision gap) and `iterations` (error per pass or
//! step).

use super::{icp, ipcrnet, lk, pcrnet};
use crate::methods::{Method, MethodError, run};
use crate::pairs::Pair;
use crate::plot::{Chart, Corner, Series};
use crate::recipes::Model;
use crate::report::{
    Context, Recorder, Report, Table, folder, label, machine, modelnet10, pair_set, success_chart,
};
use crate::{MethodScore, score};
use pcrnet_train::data::PairConfig;
use pcrnet_train::metrics;

pub(crate) fn speed(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "speed");
    let pc = rec.model("air-pcrnet")?;
    let ipc = rec.model("air-ipcrnet")?;
    let cfg = PairConfig {
        noise: Some([0.0, 0.04]),
        ..PairConfig::default()
    };
    let pairs = pair_set(
        ctx,
        "speed-airplane-noisy",
        folder(ctx, "ModelNet40-airplane", None, cfg),
    )?;
    let set = "airplane, noisy";
    // One pair at a time: the times are single-thread times.
    rec.score(set, pcrnet(), pc.f32(), &pairs, false)?;
    rec.score(set, pcrnet(), pc.int8(), &pairs, false)?;
    rec.score(set, ipcrnet(), ipc.f32(), &pairs, false)?;
    rec.score(set, ipcrnet(), ipc.int8(), &pairs, false)?;
    rec.score(set, lk(), ipc.f32(), &pairs, false)?;
    rec.score(set, icp(), None, &pairs, false)?;
    let runs = rec.runs.clone();
    let mut rows: Vec<Vec<String>> = runs
        .iter()
        .map(|r| {
            let s = &r.summary;
            let t = s.time_ms.unwrap_or_default();
            vec![
                label(&r.method, r.model.as_deref()),
                format!("{:.2}°", s.rotation_deg.mean),
                format!("{:.2}°", s.rotation_deg.std),
                format!("{:.4}", s.translation.mean),
                format!("{:.4}", s.translation.std),
                format!("{:.2}", t.mean),
                format!("{:.2}", t.std),
                format!("{:.3}", s.auc),
            ]
        })
        .collect();
    for (m, rot, ms, auc) in [
        ("paper: PCRNet (GTX 1070)", "8.82°", "1.89", "0.95"),
        ("paper: i-PCRNet", "1.03°", "146", "0.99"),
        ("paper: PointNetLK", "51.8°", "234", "0.70"),
        ("paper: ICP", "11.87°", "407", "0.93"),
    ] {
        rows.push(vec![
            m.into(),
            rot.into(),
            "".into(),
            "".into(),
            "".into(),
            ms.into(),
            "".into(),
            auc.into(),
        ]);
    }
    let header = [
        "method",
        "rot mean",
        "rot std",
        "trans mean",
        "trans std",
        "ms mean",
        "ms std",
        "AUC",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let mn10 = rec.model("mn10-pcrnet")?;
    let mn10_pairs = pair_set(ctx, "int8-mn10-noisy", modelnet10(ctx, None, cfg))?;
    let mut gap_rows = Vec::new();
    for (m, model, set, pairs) in [
        (pcrnet(), &pc, "airplane, noisy", &pairs),
        (ipcrnet(), &ipc, "airplane, noisy", &pairs),
        (pcrnet(), &mn10, "ModelNet10, noisy", &mn10_pairs),
    ] {
        let (rot, trans) = precision_gap(&m, model, pairs)?;
        gap_rows.push(vec![
            label(&m.name(None), Some(&model.name)),
            set.to_string(),
            format!("{:.3}°", rot.mean),
            format!("{:.3}°", rot.median),
            format!("{:.3}°", rot.max),
            format!("{:.4}", trans.mean),
            format!("{:.4}", trans.median),
            format!("{:.4}", trans.max),
        ]);
    }
    let gap = Table {
        caption: "How far int8 poses are from f32 poses of the same model, per pair".into(),
        header: [
            "model",
            "pairs",
            "rot mean",
            "rot median",
            "rot max",
            "trans mean",
            "trans median",
            "trans max",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect(),
        rows: gap_rows,
    };
    let raw: Vec<&MethodScore> = rec.raw.iter().map(|r| &r.1).collect();
    let chart = success_chart("Airplanes with noise: success ratio", &raw, 90.0);
    rec.plot("success", &chart)?;
    rec.finish(
        "Accuracy and time per registration (the paper's Table 1)",
        vec![
            "ModelNet40 airplanes, test split, noise sigma ~ U[0, 0.04] (the paper: car, noisy).".into(),
            format!(
                "Time: one registration at a time on one thread of this machine ({}), everything from the two clouds to the pose; the paper's times are on a GTX 1070 GPU (networks) and a CPU (ICP).",
                machine()
            ),
        ],
        vec![Table {
            caption: "Errors and time per registration (the paper's rows for reference, car category)"
                .into(),
            header,
            rows,
        }, gap],
        started,
    )
}

/// Per pair, the rotation angle and translation distance between the
/// int8 and the f32 pose of `model` under `method`.
fn precision_gap(
    method: &Method,
    model: &Model,
    pairs: &[Pair],
) -> anyhow::Result<(metrics::Stats, metrics::Stats)> {
    use rayon::prelude::*;
    let gaps: Vec<(f64, f64)> = pairs
        .par_iter()
        .map(|p| {
            let a = run(
                method,
                Some(&model.int8),
                Some(&p.template),
                &p.source,
                p.viewpoint,
            )?
            .pose;
            let b = run(
                method,
                Some(&model.f32),
                Some(&p.template),
                &p.source,
                p.viewpoint,
            )?
            .pose;
            Ok((
                metrics::rotation_error_deg(&a.rotation_matrix(), &b.rotation_matrix()),
                metrics::translation_error(&a.translation, &b.translation),
            ))
        })
        .collect::<Result<_, MethodError>>()?;
    let (rot, trans): (Vec<f64>, Vec<f64>) = gaps.into_iter().unzip();
    Ok((metrics::Stats::of(&rot), metrics::Stats::of(&trans)))
}

/// Mean rotation error after each step of a trajectory method (PointNetLK,
/// ICP), carrying the last pose forward when a registration stopped early.
fn trajectory_means(
    method: &Method,
    blob: Option<&[u8]>,
    pairs: &[Pair],
) -> anyhow::Result<Vec<f64>> {
    use rayon::prelude::*;
    let per_pair: Vec<Vec<f64>> = pairs
        .par_iter()
        .map(|p| {
            let out = run(method, blob, Some(&p.template), &p.source, p.viewpoint)?;
            let traj = out.trajectory.unwrap_or_else(|| vec![out.pose]);
            Ok((0..method.iterations)
                .map(|k| {
                    let pose = traj[k.min(traj.len().saturating_sub(1))];
                    metrics::rotation_error_deg(&pose.rotation_matrix(), &p.r_gt)
                })
                .collect())
        })
        .collect::<Result<_, MethodError>>()?;
    Ok((0..method.iterations)
        .map(|k| per_pair.iter().map(|v| v[k]).sum::<f64>() / per_pair.len().max(1) as f64)
        .collect())
}

pub(crate) fn iterations(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "iterations");
    let ipc = rec.model("mn10-ipcrnet")?;
    let trained_lk = rec.model("mn10-pointnetlk")?;
    let pairs = pair_set(
        ctx,
        "iterations",
        modelnet10(ctx, None, PairConfig::default()),
    )?;
    let passes = 20;
    let mut net = Vec::with_capacity(passes);
    for k in 1..=passes {
        let m = Method {
            iterations: k,
            ..ipcrnet()
        };
        let s = score(&m, ipc.int8(), &pairs, true)?;
        net.push(s.summary.rotation_deg.mean);
    }
    eprintln!("  i-PCRNet int8 after 1..20 passes: {net:.2?}");
    let lk_means = trajectory_means(&lk(), Some(&ipc.f32), &pairs)?;
    eprintln!("  PointNetLK after 1..20 steps: {lk_means:.2?}");
    let trained_means = trajectory_means(&lk(), trained_lk.f32().map(|b| b.1), &pairs)?;
    eprintln!("  PointNetLK (trained) after 1..20 steps: {trained_means:.2?}");
    // The device's PointNetLK on the int8 blob (its stored solver), run
    // once per count as i-PCRNet's passes are.
    let mut device_lk = Vec::with_capacity(passes);
    for k in 1..=passes {
        let m = Method {
            lk_iterations: k,
            ..Method::device_lk(false)
        };
        let s = score(&m, trained_lk.int8(), &pairs, true)?;
        device_lk.push(s.summary.rotation_deg.mean);
    }
    eprintln!("  device PointNetLK int8 after 1..20 steps: {device_lk:.2?}");
    let icp_means = trajectory_means(&icp(), None, &pairs)?;
    let curves = [
        ("i-PCRNet int8 (mn10-ipcrnet)", &net),
        ("PointNetLK (mn10-ipcrnet)", &lk_means),
        ("PointNetLK (mn10-pointnetlk)", &trained_means),
        ("device PointNetLK int8 (mn10-pointnetlk)", &device_lk),
        ("ICP", &icp_means),
    ];
    let chart = Chart {
        title: "Mean rotation error against iterations (ModelNet10)".into(),
        x_label: "iterations".into(),
        y_label: "mean rotation error (degrees)".into(),
        x_range: (1.0, icp_means.len() as f64),
        // A linear axis from 0: the means stay within one decade, where a
        // log axis would show no tick labels.
        y_range: (
            0.0,
            curves
                .iter()
                .flat_map(|c| c.1.iter())
                .copied()
                .fold(0.0, f64::max)
                * 1.15,
        ),
        series: curves
            .iter()
            .map(|(n, v)| Series {
                name: n.to_string(),
                points: v
                    .iter()
                    .enumerate()
                    .map(|(i, &e)| ((i + 1) as f64, e))
                    .collect(),
            })
            .collect(),
        log_y: false,
        legend: Corner::UpperRight,
    };
    rec.plot("rotation", &chart)?;
    let at = [1usize, 2, 3, 5, 8, 10, 20, 50, 100];
    let mut header = vec!["method".to_string()];
    header.extend(at.iter().map(|k| format!("{k}")));
    let rows = curves
        .iter()
        .map(|(n, v)| {
            let mut row = vec![n.to_string()];
            row.extend(
                at.iter()
                    .map(|&k| v.get(k - 1).map_or("".into(), |e| format!("{e:.2}°"))),
            );
            row
        })
        .collect();
    rec.finish(
        "Rotation error against iterations",
        vec![
            "ModelNet10 test split, clean sources. Mean rotation error after k iterations (a registration that stopped earlier keeps its last pose).".into(),
            "i-PCRNet: k passes of the int8 network (the run with at most k passes); PointNetLK: k Lucas-Kanade steps, on mn10-ipcrnet's f32 encoder and on mn10-pointnetlk's (trained as PointNetLK, 10 iterations, pose loss), on the host in f64; device PointNetLK int8: `pcrnet-core`'s LK steps on mn10-pointnetlk's int8 blob (its stored solver, the network's default sample of 256 points per step), the run with at most k steps; ICP: k iterations.".into(),
        ],
        vec![Table {
            caption: "Mean rotation error after k iterations".into(),
            header,
            rows,
        }],
        started,
    )
}
