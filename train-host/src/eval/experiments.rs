//! The paper's experiments, each one command (`pcrnet experiment NAME`):
//!
//! | name | question |
//! |---|---|
//! | `generalisation` | trained on 5 ModelNet10 classes: how well on the 5 others? |
//! | `noise` | Gaussian noise on the source, sigma 0 to 0.06 |
//! | `partial` | 20, 50, 70% of the source cut away by a plane (ModelNet40 airplanes), networks trained with and without partial data, with and without ICP refinement |
//! | `sparse` | only 100% down to 5% of the source's points |
//! | `speed` | the paper's Table 1: errors, time and AUC of every method on one category with noise |
//! | `iterations` | rotation error against iteration count for i-PCRNet, PointNetLK and ICP |
//! | `trust` | the shipped model's device pipeline: flips, refinement, and how well its residual flags bad poses |
//! | `heldout` | five-class training with and without more varied shapes added, on the five classes held out |
//! | `resampled` | the paper's protocol beside sources sampled apart from the template, clean, noisy and single-view, generic and object-specific |
//!
//! An experiment trains the models it needs when they are missing (the
//! [`super::recipes::Recipe`]s, into `<work>/models/<name>/`, resumable), makes or reloads
//! its seeded pair sets (`<work>/pairs/<set>.json`, see [`super::pairs`]),
//! scores every method on exactly the same pairs, and writes
//! `<results>/<name>.json` (a [`Report`]) with PNG and SVG plots beside
//! it. Per-pair scores go to `<work>/runs/<name>.json`. `pcrnet results`
//! turns the reports into `RESULTS.md` ([`render_results`]).
//!
//! All networks are the embedded architecture (int8 blob under 256 KiB)
//! at 512 points per cloud; every set, model and pair is fixed by
//! [`Context::seed`].

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

use super::methods::{Method, MethodKind, run};
use super::metrics::{self, Summary};
use super::pairs::{Pair, PairSet, PairSetSpec, Shapes};
use super::plot::{Chart, Corner, Series, draw};
use super::recipes::{Model, NamedBlob, PARTIAL_RECIPE, Recipe};
use super::{MethodScore, score};
use crate::train::data::{PairConfig, Sampling};

/// Points per cloud in every experiment (as the models are trained).
pub const POINTS: usize = 512;

/// The experiment names, in order.
pub const EXPERIMENTS: [&str; 9] = [
    "generalisation",
    "noise",
    "partial",
    "sparse",
    "speed",
    "iterations",
    "trust",
    "resampled",
    "heldout",
];

/// Where an experiment reads and writes.
#[derive(Debug, Clone)]
pub struct Context {
    /// Data root holding `ModelNet10/` and `ModelNet40-airplane/`.
    pub data: PathBuf,
    /// Models, pair sets and per-pair scores.
    pub work: PathBuf,
    /// Reports and plots (the repository's `results/`).
    pub results: PathBuf,
    /// Pairs per set.
    pub pairs: usize,
    /// Seed of every pair set.
    pub seed: u64,
}

/// Makes (or reloads and checks) pair set `name`.
pub(super) fn pair_set(ctx: &Context, name: &str, spec: PairSetSpec) -> anyhow::Result<Vec<Pair>> {
    let path = ctx.work.join("pairs").join(format!("{name}.json"));
    let shapes = spec.load_shapes()?;
    let set = if path.is_file() {
        let set = PairSet::load(&path)?;
        let same = |a: &PairSetSpec, b: &PairSetSpec| {
            let strip = |s: &PairSetSpec| {
                let mut s = s.clone();
                if let Shapes::Folder { root, .. } = &mut s.shapes {
                    *root = PathBuf::new();
                }
                s
            };
            strip(a) == strip(b)
        };
        anyhow::ensure!(
            same(&set.spec, &spec),
            "{} was made by another recipe; delete it to remake it",
            path.display()
        );
        set
    } else {
        let set = PairSet::generate(spec, &shapes);
        set.save(&path)?;
        set
    };
    Ok(set.materialise(&shapes)?)
}

pub(super) fn modelnet10(
    ctx: &Context,
    classes: Option<&[&str]>,
    pairs: PairConfig,
) -> PairSetSpec {
    folder(ctx, "ModelNet10", classes, pairs)
}

/// The test split of `<data>/<dir>` (only `classes` when given), at the
/// experiments' [`POINTS`].
pub(super) fn folder(
    ctx: &Context,
    dir: &str,
    classes: Option<&[&str]>,
    pairs: PairConfig,
) -> PairSetSpec {
    let shapes = Shapes::Folder {
        root: ctx.data.join(dir),
        test_split: true,
        classes: classes.map(|c| c.iter().map(|s| s.to_string()).collect()),
    };
    pair_spec(ctx, shapes, POINTS, pairs)
}

/// An experiment's pair set of `shapes` at `points` per cloud: the
/// context's pair count and seed, sources not centred or resampled.
pub(super) fn pair_spec(
    ctx: &Context,
    shapes: Shapes,
    points: usize,
    pairs: PairConfig,
) -> PairSetSpec {
    PairSetSpec {
        shapes,
        points,
        sampling: Sampling::Fps,
        pairs: PairConfig {
            centre: false,
            ..pairs
        },
        count: ctx.pairs,
        seed: ctx.seed,
        resample: false,
    }
}

/// A table of a report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table {
    /// What it shows.
    pub caption: String,
    /// Column names.
    pub header: Vec<String>,
    /// Rows of formatted cells.
    pub rows: Vec<Vec<String>>,
}

/// One method scored on one set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Run {
    /// The set (`sigma 0.02`, `unseen classes`, ...).
    pub set: String,
    /// Method name.
    pub method: String,
    /// Model, for network methods.
    pub model: Option<String>,
    /// The summary.
    pub summary: Summary,
    /// Registrations that failed (scored as the identity pose).
    pub failures: usize,
}

/// Where and how an experiment ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// `git describe`-style commit of the code that ran (`-dirty` when modified).
    pub commit: String,
    /// CPU model and threads.
    pub machine: String,
    /// The data root.
    pub data: String,
    /// Seed of the pair sets.
    pub seed: u64,
    /// Pairs per set.
    pub pairs: usize,
    /// Models used, with their training commands.
    pub models: Vec<(String, String)>,
    /// Wall time of the experiment, seconds.
    pub seconds: f64,
}

/// What an experiment produced (`<results>/<name>.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Experiment name.
    pub name: String,
    /// Title.
    pub title: String,
    /// Setup, one line each.
    pub setup: Vec<String>,
    /// Result tables.
    pub tables: Vec<Table>,
    /// Plots (PNG file names in the results folder; an SVG sits beside each).
    pub plots: Vec<String>,
    /// Every summary.
    pub runs: Vec<Run>,
    /// Where and how it ran.
    pub provenance: Provenance,
}

/// Collects an experiment's results as it runs.
pub(super) struct Recorder<'a> {
    pub(super) ctx: &'a Context,
    name: &'static str,
    runs: Vec<Run>,
    pub(super) raw: Vec<(String, MethodScore)>,
    plots: Vec<String>,
    models: Vec<(String, String)>,
}

impl<'a> Recorder<'a> {
    pub(super) fn new(ctx: &'a Context, name: &'static str) -> Self {
        Recorder {
            ctx,
            name,
            runs: Vec::new(),
            raw: Vec::new(),
            plots: Vec::new(),
            models: Vec::new(),
        }
    }

    pub(super) fn model(&mut self, name: &str) -> anyhow::Result<Model> {
        let m = super::recipes::model(self.ctx, name)?;
        if let Some(r) = Recipe::named(name) {
            let cmd = r.command(&self.ctx.data, &self.ctx.work.join("models").join(name));
            self.models
                .push((name.to_string(), format!("pcrnet train {}", cmd.join(" "))));
        }
        Ok(m)
    }

    /// Scores `method` on `pairs`, records it and returns its summary.
    pub(super) fn score(
        &mut self,
        set: &str,
        method: Method,
        model: Option<NamedBlob<'_>>,
        pairs: &[Pair],
        parallel: bool,
    ) -> anyhow::Result<Summary> {
        let s = score(&method, model, pairs, parallel)?;
        eprintln!(
            "  {set:<18} {:<28} rot {:7.3} / {:7.3} deg  trans {:.4}  AUC {:.4}",
            label(&s.method, s.model.as_deref()),
            s.summary.rotation_deg.mean,
            s.summary.rotation_deg.median,
            s.summary.translation.mean,
            s.summary.auc
        );
        self.runs.push(Run {
            set: set.to_string(),
            method: s.method.clone(),
            model: s.model.clone(),
            summary: s.summary.clone(),
            failures: s.failures.len(),
        });
        for f in &s.failures {
            eprintln!("    failed (scored as identity): {f}");
        }
        let summary = s.summary.clone();
        self.raw.push((set.to_string(), s));
        Ok(summary)
    }

    pub(super) fn plot(&mut self, stem: &str, chart: &Chart) -> anyhow::Result<()> {
        std::fs::create_dir_all(&self.ctx.results)?;
        let name = format!("{}-{stem}", self.name);
        draw(chart, &self.ctx.results.join(&name))?;
        self.plots.push(format!("{name}.png"));
        Ok(())
    }

    pub(super) fn finish(
        self,
        title: &str,
        setup: Vec<String>,
        tables: Vec<Table>,
        started: std::time::Instant,
    ) -> anyhow::Result<Report> {
        let report = Report {
            name: self.name.to_string(),
            title: title.to_string(),
            setup,
            tables,
            plots: self.plots,
            runs: self.runs,
            provenance: Provenance {
                commit: commit(),
                machine: machine(),
                data: self.ctx.data.display().to_string(),
                seed: self.ctx.seed,
                pairs: self.ctx.pairs,
                models: self.models,
                seconds: started.elapsed().as_secs_f64(),
            },
        };
        let write = |path: PathBuf, json: String| -> anyhow::Result<()> {
            if let Some(d) = path.parent() {
                std::fs::create_dir_all(d)?;
            }
            std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))
        };
        write(
            self.ctx.results.join(format!("{}.json", self.name)),
            serde_json::to_string_pretty(&report)?,
        )?;
        write(
            self.ctx
                .work
                .join("runs")
                .join(format!("{}.json", self.name)),
            serde_json::to_string(&self.raw)?,
        )?;
        Ok(report)
    }
}

pub(super) fn label(method: &str, model: Option<&str>) -> String {
    match model {
        Some(m) => format!("{method} ({m})"),
        None => method.to_string(),
    }
}

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

fn commit() -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(c) => {
            let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty { format!("{c}-dirty") } else { c }
        }
        None => "unknown".into(),
    }
}

fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{cpu}, {threads} threads")
}

/// A success-ratio chart (rotation threshold 0 to `max_deg`).
pub(super) fn success_chart(title: &str, runs: &[&MethodScore], max_deg: f64) -> Chart {
    Chart {
        title: title.to_string(),
        x_label: "rotation error threshold (degrees)".into(),
        y_label: "success ratio".into(),
        x_range: (0.0, max_deg),
        y_range: (0.0, 1.02),
        series: runs
            .iter()
            .map(|s| {
                let rot: Vec<f64> = s.pairs.iter().map(|p| p.rot_deg).collect();
                Series {
                    name: label(&s.method, s.model.as_deref()),
                    points: metrics::success_curve(&rot)
                        .into_iter()
                        .filter(|&(x, _)| x <= max_deg)
                        .collect(),
                }
            })
            .collect(),
        log_y: false,
        legend: Corner::LowerRight,
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

/// Runs experiment `name` (one of [`EXPERIMENTS`]).
pub fn run_experiment(ctx: &Context, name: &str) -> anyhow::Result<Report> {
    match name {
        "generalisation" => generalisation(ctx),
        "noise" => noise(ctx),
        "partial" => partial(ctx),
        "sparse" => sparse(ctx),
        "speed" => speed(ctx),
        "iterations" => iterations(ctx),
        "trust" => super::trust::trust(ctx),
        "resampled" => super::resampled::resampled(ctx),
        "heldout" => super::heldout::heldout(ctx),
        other => anyhow::bail!(
            "unknown experiment {other} (one of {})",
            EXPERIMENTS.join(", ")
        ),
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

pub(super) const SEEN: [&str; 5] = ["bathtub", "bed", "chair", "desk", "dresser"];
pub(super) const UNSEEN: [&str; 5] = ["monitor", "night_stand", "sofa", "table", "toilet"];

fn generalisation(ctx: &Context) -> anyhow::Result<Report> {
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

fn noise(ctx: &Context) -> anyhow::Result<Report> {
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

fn partial(ctx: &Context) -> anyhow::Result<Report> {
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

fn sparse(ctx: &Context) -> anyhow::Result<Report> {
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

fn speed(ctx: &Context) -> anyhow::Result<Report> {
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

fn iterations(ctx: &Context) -> anyhow::Result<Report> {
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

/// Renders `RESULTS.md` from the reports in `results` (experiments in
/// [`EXPERIMENTS`] order; missing ones are listed as not run).
pub fn render_results(results: &Path) -> anyhow::Result<String> {
    let mut md = String::from(
        "# Results\n\nGenerated by `pcrnet results` from the experiment reports in `results/` \
         (each written by `pcrnet experiment NAME`; see the README). Every number below is \
         what that run produced; the JSON beside each plot holds the same numbers.\n\n\
         Times: only the `speed` table's are single-thread times on a quiet machine. \
         The `ms mean` column of the other tables comes from runs with two pairs at \
         once on the 2 cores, sometimes beside a training job; use it only to compare \
         methods within one run.\n\n",
    );
    let mut missing = Vec::new();
    for name in EXPERIMENTS {
        let path = results.join(format!("{name}.json"));
        if !path.is_file() {
            missing.push(name);
            continue;
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let r: Report =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        md.push_str(&format!("## {} (`{}`)\n\n", r.title, r.name));
        for line in &r.setup {
            md.push_str(&format!("- {line}\n"));
        }
        let p = &r.provenance;
        md.push_str(&format!(
            "- Run: commit `{}`, {}, data `{}`, seed {}, {} pairs per set, {:.0} s.\n",
            p.commit, p.machine, p.data, p.seed, p.pairs, p.seconds
        ));
        for (m, cmd) in &p.models {
            md.push_str(&format!("- Model `{m}`: `{cmd}`\n"));
        }
        md.push('\n');
        for t in &r.tables {
            md.push_str(&format!("{}:\n\n", t.caption));
            md.push_str(&format!("| {} |\n", t.header.join(" | ")));
            md.push_str(&format!("|{}\n", "---|".repeat(t.header.len())));
            for row in &t.rows {
                md.push_str(&format!("| {} |\n", row.join(" | ")));
            }
            md.push('\n');
        }
        for plot in &r.plots {
            md.push_str(&format!("![{plot}]({}/{plot})\n\n", results.display()));
        }
    }
    if !missing.is_empty() {
        md.push_str(&format!("Not run yet: {}.\n", missing.join(", ")));
    }
    Ok(md)
}
