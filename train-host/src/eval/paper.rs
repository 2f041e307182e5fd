//! The experiments that repeat the paper's (Sarode et al. 2020):
//! `generalisation`, `noise`, `partial`, `sparse`, `speed` (its Table 1)
//! and `iterations`. They run on [`super::experiments`]' framework (pair
//! sets, models, reports); this project's own questions are in
//! [`super::trust`], [`super::resampled`] and [`super::heldout`].

use super::experiments::{
    Context, Recorder, Report, Run, SEEN, Table, UNSEEN, folder, label, machine, modelnet10,
    pair_set, success_chart,
};
use super::methods::{Method, MethodKind, run};
use super::metrics::{self, Summary};
use super::pairs::{Pair, PairSetSpec};
use super::plot::{Chart, Corner, Series};
use super::recipes::{Model, NamedBlob, PARTIAL_RECIPE};
use super::{MethodScore, score};
use crate::train::data::PairConfig;

/// The summary table's header.
fn summary_header(first: &str) -> Vec<String> {
    [
        first,
        "method",
        "rot mean",
        "rot median",
        "rot std",
        "trans mean",
        "trans median",
        "AUC",
        "ok (5°, 0.05)",
        "ok (10°, 0.1)",
        "ok (20°, 0.2)",
        "ms mean",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn summary_row(set: &str, run: &Run) -> Vec<String> {
    let s = &run.summary;
    let failed = if run.failures > 0 {
        format!(", {} failed", run.failures)
    } else {
        String::new()
    };
    let mut row = vec![
        set.to_string(),
        format!("{}{failed}", label(&run.method, run.model.as_deref())),
        format!("{:.2}°", s.rotation_deg.mean),
        format!("{:.2}°", s.rotation_deg.median),
        format!("{:.2}°", s.rotation_deg.std),
        format!("{:.4}", s.translation.mean),
        format!("{:.4}", s.translation.median),
        format!("{:.3}", s.auc),
    ];
    row.extend(s.success.iter().map(|x| format!("{:.2}", x.ratio)));
    row.push(s.time_ms.map_or("-".into(), |t| format!("{:.1}", t.mean)));
    row
}

fn summary_table(caption: &str, first: &str, runs: &[Run]) -> Table {
    Table {
        caption: caption.to_string(),
        header: summary_header(first),
        rows: runs.iter().map(|r| summary_row(&r.set, r)).collect(),
    }
}

/// A chart of one summary value against a swept parameter.
fn sweep_chart(
    title: &str,
    x_label: &str,
    y_label: &str,
    sets: &[SweepSet],
    runs: &[Run],
    value: impl Fn(&Summary) -> f64,
) -> Chart {
    let mut names: Vec<String> = Vec::new();
    for r in runs {
        let l = label(&r.method, r.model.as_deref());
        if !names.contains(&l) {
            names.push(l);
        }
    }
    let series = names
        .iter()
        .map(|n| Series {
            name: n.clone(),
            points: sets
                .iter()
                .filter_map(|set| {
                    runs.iter()
                        .find(|r| r.set == set.name && &label(&r.method, r.model.as_deref()) == n)
                        .map(|r| (set.x, value(&r.summary)))
                })
                .collect(),
        })
        .collect();
    let lo = sets.iter().map(|s| s.x).fold(f64::INFINITY, f64::min);
    let hi = sets.iter().map(|s| s.x).fold(f64::NEG_INFINITY, f64::max);
    Chart {
        title: title.to_string(),
        x_label: x_label.to_string(),
        y_label: y_label.to_string(),
        x_range: (lo, hi),
        y_range: (0.0, 1.02),
        series,
        log_y: false,
        legend: Corner::LowerLeft,
    }
}

fn icp() -> Method {
    Method::new(MethodKind::Icp)
}
fn pcrnet() -> Method {
    Method::new(MethodKind::Pcrnet)
}
fn ipcrnet() -> Method {
    Method::new(MethodKind::Ipcrnet)
}
fn lk() -> Method {
    Method::new(MethodKind::Pointnetlk)
}

pub(super) fn generalisation(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "generalisation");
    let gen5 = rec.model("mn10-seen5-ipcrnet")?;
    let toilet = rec.model("mn10-toilet-ipcrnet")?;
    let clean = PairConfig::default();
    let sets: [(&str, &[&str]); 3] = [
        ("seen classes", &SEEN),
        ("unseen classes", &UNSEEN),
        ("toilet (unseen)", &["toilet"]),
    ];
    for (set, classes) in sets {
        let pairs = pair_set(
            ctx,
            &format!("gen-{}", set.split(' ').next().unwrap_or(set)),
            modelnet10(ctx, Some(classes), clean),
        )?;
        rec.score(set, icp(), None, &pairs, true)?;
        rec.score(set, lk(), gen5.f32(), &pairs, true)?;
        rec.score(set, ipcrnet(), gen5.f32(), &pairs, true)?;
        rec.score(set, ipcrnet(), gen5.int8(), &pairs, true)?;
        if classes == ["toilet"] {
            rec.score(set, ipcrnet(), toilet.int8(), &pairs, true)?;
        }
        let first = rec.raw.len() - if classes == ["toilet"] { 5 } else { 4 };
        let runs: Vec<&MethodScore> = rec.raw[first..].iter().map(|r| &r.1).collect();
        let chart = success_chart(&format!("Generalisation: {set}"), &runs, 90.0);
        rec.plot(set.split(' ').next().unwrap_or(set), &chart)?;
    }
    let table = summary_table(
        "Trained on bathtub, bed, chair, desk, dresser (mn10-seen5-ipcrnet); tested on those classes and on the other five; mn10-toilet-ipcrnet is trained on toilets only",
        "test set",
        &rec.runs,
    );
    rec.finish(
        "Generalisation to unseen categories",
        vec![
            "ModelNet10, test split, clean sources, Euler angles U[-45°, 45°], translation U[-1, 1].".into(),
            format!("Seen: {}. Unseen: {}.", SEEN.join(", "), UNSEEN.join(", ")),
            "i-PCRNet: up to 20 passes, stopping at ||dT - I||_F < 1e-7. PointNetLK uses the same model's f32 encoder.".into(),
        ],
        vec![table],
        started,
    )
}

/// Runs `methods` over a sweep of pair sets made from one recipe.
fn sweep(
    rec: &mut Recorder<'_>,
    set_prefix: &str,
    sets: &[SweepSet],
    methods: &[(Method, Option<NamedBlob<'_>>)],
) -> anyhow::Result<()> {
    for set in sets {
        let pairs = pair_set(
            rec.ctx,
            &format!("{set_prefix}-{}", set.name),
            set.spec.clone(),
        )?;
        for (m, model) in methods {
            rec.score(&set.name, *m, *model, &pairs, true)?;
        }
    }
    Ok(())
}

/// One point of a sweep: its value on the x axis, its name, its pairs.
struct SweepSet {
    x: f64,
    name: String,
    spec: PairSetSpec,
}

pub(super) fn noise(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "noise");
    let pc = rec.model("mn10-pcrnet")?;
    let ipc = rec.model("mn10-ipcrnet")?;
    let sigmas = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06];
    let sets: Vec<SweepSet> = sigmas
        .iter()
        .map(|&s| {
            let cfg = PairConfig {
                noise: (s > 0.0).then_some([s, s]),
                ..PairConfig::default()
            };
            SweepSet {
                x: s as f64,
                name: format!("sigma {s:.2}"),
                spec: modelnet10(ctx, None, cfg),
            }
        })
        .collect();
    let methods = [
        (icp(), None),
        (lk(), ipc.f32()),
        (pcrnet(), pc.int8()),
        (ipcrnet(), ipc.int8()),
        (ipcrnet().then_icp(), ipc.int8()),
    ];
    sweep(&mut rec, "noise", &sets, &methods)?;
    for (stem, what, f) in [
        ("auc", "AUC", (|s: &Summary| s.auc) as fn(&Summary) -> f64),
        ("success", "success ratio (10°, 0.1)", |s: &Summary| {
            s.success[1].ratio
        }),
    ] {
        let chart = sweep_chart(
            &format!("Gaussian noise on the source: {what}"),
            "noise standard deviation",
            what,
            &sets,
            &rec.runs,
            f,
        );
        rec.plot(stem, &chart)?;
    }
    let table = summary_table("Errors per noise level", "noise", &rec.runs);
    rec.finish(
        "Gaussian noise on the source",
        vec![
            "ModelNet10 test split (all 10 classes), the same templates and transforms at every noise level; noise N(0, sigma^2) per coordinate.".into(),
            "Networks trained on ModelNet10 with sigma ~ U[0, 0.04]. PointNetLK uses mn10-ipcrnet's f32 encoder.".into(),
        ],
        vec![table],
        started,
    )
}

pub(super) fn partial(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "partial");
    let full = rec.model("air-ipcrnet")?;
    let part = rec.model(PARTIAL_RECIPE.name)?;
    let cuts = [0.0, 0.2, 0.5, 0.7];
    let sets: Vec<SweepSet> = cuts
        .iter()
        .map(|&c| {
            let keep = 1.0 - c;
            let cfg = PairConfig {
                partial: (c > 0.0).then_some([keep, keep]),
                ..PairConfig::default()
            };
            SweepSet {
                x: c as f64 * 100.0,
                name: format!("{:.0}% cut", c * 100.0),
                spec: folder(ctx, "ModelNet40-airplane", None, cfg),
            }
        })
        .collect();
    let methods = [
        (icp(), None),
        (ipcrnet(), full.int8()),
        (ipcrnet().then_icp(), full.int8()),
        (ipcrnet(), part.int8()),
        (ipcrnet().then_icp(), part.int8()),
    ];
    sweep(&mut rec, "partial", &sets, &methods)?;
    let chart = sweep_chart(
        "Partial source (ModelNet40 airplanes): AUC",
        "part of the source removed (%)",
        "AUC",
        &sets,
        &rec.runs,
        |s| s.auc,
    );
    rec.plot("auc", &chart)?;
    let table = summary_table("Errors per incompleteness", "cut", &rec.runs);
    rec.finish(
        "Partial source",
        vec![
            "ModelNet40 airplanes, test split (100 shapes; pairs repeat shapes with new transforms). A plane with a random normal cuts away the given share of the source's points (then padded back to 512 by repeats); no noise.".into(),
            "air-ipcrnet is trained on full sources, air-partial-ipcrnet on sources keeping 30-80%; both with noise U[0, 0.04]. + ICP: ICP (100 iterations) starts from the network's pose.".into(),
        ],
        vec![table],
        started,
    )
}

pub(super) fn sparse(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "sparse");
    let pc = rec.model("mn10-pcrnet")?;
    let ipc = rec.model("mn10-ipcrnet")?;
    let keeps = [1.0, 0.5, 0.25, 0.1, 0.05];
    let sets: Vec<SweepSet> = keeps
        .iter()
        .map(|&k| {
            let cfg = PairConfig {
                sparse: (k < 1.0).then_some([k, k]),
                ..PairConfig::default()
            };
            SweepSet {
                x: k as f64 * 100.0,
                name: format!("{:.0}% kept", k * 100.0),
                spec: modelnet10(ctx, None, cfg),
            }
        })
        .collect();
    let methods = [
        (icp(), None),
        (lk(), ipc.f32()),
        (pcrnet(), pc.int8()),
        (ipcrnet(), ipc.int8()),
        (ipcrnet().then_icp(), ipc.int8()),
    ];
    sweep(&mut rec, "sparse", &sets, &methods)?;
    let chart = sweep_chart(
        "Sparse source (ModelNet10): AUC",
        "points of the source kept (%)",
        "AUC",
        &sets,
        &rec.runs,
        |s| s.auc,
    );
    rec.plot("auc", &chart)?;
    let table = summary_table("Errors per density", "density", &rec.runs);
    rec.finish(
        "Sparse source",
        vec![
            "ModelNet10 test split; the source keeps a random subset of its 512 points (padded back to 512 by repeats, which max-pooling ignores); no noise.".into(),
            "Networks trained on full sources with noise.".into(),
        ],
        vec![table],
        started,
    )
}

pub(super) fn speed(ctx: &Context) -> anyhow::Result<Report> {
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
            let a = run(method, Some(&model.int8), Some(&p.template), &p.source)?.pose;
            let b = run(method, Some(&model.f32), Some(&p.template), &p.source)?.pose;
            Ok((
                metrics::rotation_error_deg(&a.rotation_matrix(), &b.rotation_matrix()),
                metrics::translation_error(&a.translation, &b.translation),
            ))
        })
        .collect::<Result<_, super::methods::MethodError>>()?;
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
            let out = run(method, blob, Some(&p.template), &p.source)?;
            let traj = out.trajectory.unwrap_or_else(|| vec![out.pose]);
            Ok((0..method.iterations)
                .map(|k| {
                    let pose = traj[k.min(traj.len().saturating_sub(1))];
                    metrics::rotation_error_deg(&pose.rotation_matrix(), &p.r_gt)
                })
                .collect())
        })
        .collect::<Result<_, super::methods::MethodError>>()?;
    Ok((0..method.iterations)
        .map(|k| per_pair.iter().map(|v| v[k]).sum::<f64>() / per_pair.len().max(1) as f64)
        .collect())
}

pub(super) fn iterations(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "iterations");
    let ipc = rec.model("mn10-ipcrnet")?;
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
    let icp_means = trajectory_means(&icp(), None, &pairs)?;
    let curves = [
        ("i-PCRNet int8 (mn10-ipcrnet)", &net),
        ("PointNetLK (mn10-ipcrnet)", &lk_means),
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
            "i-PCRNet: k passes of the int8 network (the run with at most k passes); PointNetLK: k Lucas-Kanade steps; ICP: k iterations.".into(),
        ],
        vec![Table {
            caption: "Mean rotation error after k iterations".into(),
            header,
            rows,
        }],
        started,
    )
}
