//! What the experiments share: where they read and write ([`Context`]),
//! how they collect their results (`Recorder`) and what they write
//! ([`Report`], with its [`Table`]s, [`Run`]s and [`Provenance`]). Below
//! every experiment; `experiments` dispatches to them and renders the
//! reports.

use std::path::PathBuf;

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

use super::methods::Method;
use super::pairs::{Pair, PairSet, PairSetSpec, Shapes};
use super::plot::{Chart, Corner, Series, draw};
use super::{MethodScore, score};
use pcrnet_train::data::{PairConfig, Sampling};
use pcrnet_train::metrics::{self, Summary};

/// Points per cloud in every experiment (as the models are trained).
pub const POINTS: usize = 512;

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
    /// Pairs per set; 0 when the experiment reads no pair sets (it makes
    /// its own sequences or frames).
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
    pub(super) runs: Vec<Run>,
    pub(super) raw: Vec<(String, MethodScore)>,
    plots: Vec<String>,
    /// The models used, with their training commands ([`Recorder::model`]
    /// in `recipes`, which loads and records them).
    pub(crate) models: Vec<(String, String)>,
    /// Pairs per set, as the report states it (0: no pair sets).
    pairs: usize,
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
            pairs: ctx.pairs,
        }
    }

    /// For an experiment that reads no pair sets (it makes its own sequences
    /// or frames): the report does not state a pair count.
    pub(super) fn without_pair_sets(mut self) -> Self {
        self.pairs = 0;
        self
    }

    /// The experiment's name (its reports' and pair sets' prefix).
    pub(super) fn name(&self) -> &'static str {
        self.name
    }

    /// Scores `method` on `pairs`, records it and returns its summary.
    pub(super) fn score(
        &mut self,
        set: &str,
        method: Method,
        model: Option<crate::NamedBlob<'_>>,
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

    /// Writes a picture `write` makes (PNG) beside the plots, listed with them.
    pub(super) fn picture(
        &mut self,
        stem: &str,
        write: impl FnOnce(&std::path::Path) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        std::fs::create_dir_all(&self.ctx.results)?;
        let name = format!("{}-{stem}.png", self.name);
        write(&self.ctx.results.join(&name))?;
        self.plots.push(name);
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
                pairs: self.pairs,
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

/// The commit the code ran from, `-dirty` if a tracked file outside the
/// experiments' own output (`results/`, `RESULTS.md`, which every run
/// rewrites) differs from it.
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
            let dirty = git(&[
                "status",
                "--porcelain",
                "--untracked-files=no",
                "--",
                ":(top,exclude)results",
                ":(top,exclude)RESULTS.md",
            ])
            .is_some_and(|s| !s.is_empty());
            if dirty { format!("{c}-dirty") } else { c }
        }
        None => "unknown".into(),
    }
}

pub(super) fn machine() -> String {
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

pub(super) const SEEN: [&str; 5] = ["bathtub", "bed", "chair", "desk", "dresser"];
pub(super) const UNSEEN: [&str; 5] = ["monitor", "night_stand", "sofa", "table", "toilet"];
