//! The paper's sweeps: `noise`, `partial` and `sparse`, each one recipe of
//! pair sets over a swept value, its charts and its summary table.

use super::{icp, ipcrnet, lk, pcrnet, summary_table};
use crate::NamedBlob;
use crate::methods::Method;
use crate::pairs::PairSetSpec;
use crate::plot::{Chart, Corner, Series};
use crate::recipes::{Model, PARTIAL_RECIPE};
use crate::report::{Context, Recorder, Report, Run, folder, label, modelnet10, pair_set};
use pcrnet_train::data::PairConfig;
use pcrnet_train::metrics::Summary;

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

/// Runs `methods` over a sweep of pair sets made from one recipe, then
/// plots `charts` against the swept value and reports the summary table.
fn sweep(
    mut rec: Recorder<'_>,
    sets: &[SweepSet],
    methods: &[(Method, Option<NamedBlob<'_>>)],
    report: SweepReport<'_>,
    started: std::time::Instant,
) -> anyhow::Result<Report> {
    for set in sets {
        let pairs = pair_set(
            rec.ctx,
            &format!("{}-{}", rec.name(), set.name),
            set.spec.clone(),
        )?;
        for (m, model) in methods {
            rec.score(&set.name, *m, *model, &pairs, true)?;
        }
    }
    for chart in report.charts {
        let plotted = sweep_chart(
            &format!("{}: {}", report.subject, chart.what),
            report.x_label,
            chart.what,
            sets,
            &rec.runs,
            chart.value,
        );
        rec.plot(chart.stem, &plotted)?;
    }
    let (caption, first) = report.table;
    let table = summary_table(caption, first, &rec.runs);
    rec.finish(report.title, report.notes, vec![table], started)
}

/// The methods the ModelNet10 sweeps compare: ICP, PointNetLK on the
/// i-PCRNet's f32 encoder, PCRNet, i-PCRNet and i-PCRNet + ICP (int8).
fn modelnet10_methods<'m>(pc: &'m Model, ipc: &'m Model) -> [(Method, Option<NamedBlob<'m>>); 5] {
    [
        (icp(), None),
        (lk(), ipc.f32()),
        (pcrnet(), pc.int8()),
        (ipcrnet(), ipc.int8()),
        (ipcrnet().then_icp(), ipc.int8()),
    ]
}

/// One point of a sweep: its value on the x axis, its name, its pairs.
struct SweepSet {
    x: f64,
    name: String,
    spec: PairSetSpec,
}

/// What a sweep reports: its title and notes, the subject and x axis of
/// its charts, the charts, and the summary table's caption and first
/// column.
struct SweepReport<'a> {
    title: &'a str,
    notes: Vec<String>,
    subject: &'a str,
    x_label: &'a str,
    charts: &'a [SweepChart],
    table: (&'a str, &'a str),
}

/// A chart of one summary value over a sweep: its file stem, what it
/// shows (the y axis) and how to read it from a summary.
struct SweepChart {
    stem: &'static str,
    what: &'static str,
    value: fn(&Summary) -> f64,
}

/// The AUC over a sweep.
const AUC_CHART: SweepChart = SweepChart {
    stem: "auc",
    what: "AUC",
    value: |s| s.auc,
};

pub(crate) fn noise(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "noise");
    let pc = rec.model("mn10-pcrnet")?;
    let ipc = rec.model("mn10-ipcrnet")?;
    let trained_lk = rec.model("mn10-pointnetlk")?;
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
    let mut methods = modelnet10_methods(&pc, &ipc).to_vec();
    methods.insert(2, (lk(), trained_lk.f32()));
    methods.insert(3, (Method::device_lk(false), trained_lk.int8()));
    let report = SweepReport {
        title: "Gaussian noise on the source",
        notes: vec![
            "ModelNet10 test split (all 10 classes), the same templates and transforms at every noise level; noise N(0, sigma^2) per coordinate.".into(),
            "Networks trained on ModelNet10 with sigma ~ U[0, 0.04]. PointNetLK twice on the host: on mn10-ipcrnet's f32 encoder, and trained as PointNetLK (mn10-pointnetlk: 10 Lucas-Kanade iterations, pose loss); and mn10-pointnetlk's int8 blob through the device pipeline (20 LK steps, K=1, scored, no ICP).".into(),
        ],
        subject: "Gaussian noise on the source",
        x_label: "noise standard deviation",
        charts: &[
            AUC_CHART,
            SweepChart {
                stem: "success",
                what: "success ratio (10°, 0.1)",
                value: |s| s.success[1].ratio,
            },
        ],
        table: ("Errors per noise level", "noise"),
    };
    sweep(rec, &sets, &methods, report, started)
}

pub(crate) fn partial(ctx: &Context) -> anyhow::Result<Report> {
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
    let report = SweepReport {
        title: "Partial source",
        notes: vec![
            "ModelNet40 airplanes, test split (100 shapes; pairs repeat shapes with new transforms). A plane with a random normal cuts away the given share of the source's points (then padded back to 512 by repeats); no noise.".into(),
            "air-ipcrnet is trained on full sources, air-partial-ipcrnet on sources keeping 30-80%; both with noise U[0, 0.04]. + ICP: ICP (100 iterations) starts from the network's pose.".into(),
        ],
        subject: "Partial source (ModelNet40 airplanes)",
        x_label: "part of the source removed (%)",
        charts: &[AUC_CHART],
        table: ("Errors per incompleteness", "cut"),
    };
    sweep(rec, &sets, &methods, report, started)
}

pub(crate) fn sparse(ctx: &Context) -> anyhow::Result<Report> {
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
    let methods = modelnet10_methods(&pc, &ipc);
    let report = SweepReport {
        title: "Sparse source",
        notes: vec![
            "ModelNet10 test split; the source keeps a random subset of its 512 points (padded back to 512 by repeats, which max-pooling ignores); no noise.".into(),
            "Networks trained on full sources with noise.".into(),
        ],
        subject: "Sparse source (ModelNet10)",
        x_label: "points of the source kept (%)",
        charts: &[AUC_CHART],
        table: ("Errors per density", "density"),
    };
    sweep(rec, &sets, &methods, report, started)
}
