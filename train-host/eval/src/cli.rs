//! The evaluation commands: `pairs` (make a saved test set), `eval` (score
//! a method on a set), `experiment NAME` and `results` (RESULTS.md).

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;

use super::methods::{Method, MethodKind};
use super::pairs::{PairSet, PairSetSpec, Shapes};
use crate::experiments::{self, EXPERIMENTS};
use crate::report::{self, Context};
use pcrnet_train::cli::PairArgs;
use pcrnet_train::data::Sampling;

/// Arguments of `pcrnet pairs`.
#[derive(Debug, Clone, Args)]
pub struct PairsArgs {
    /// ModelNet-style folder (`<root>/<class>/<split>/*` or `<root>/<split>/*`)
    /// holding your own clouds in any format `pcrnet` reads.
    #[arg(long, conflicts_with = "generated")]
    pub data: Option<PathBuf>,
    /// Use this many generated shapes instead (no files needed).
    #[arg(long, conflicts_with = "object", allow_negative_numbers = true)]
    pub generated: Option<usize>,
    /// Poses of one object of your own instead (a cloud or an OFF mesh, as
    /// `train --object`); with --count, that many pairs.
    #[arg(long, conflicts_with_all = ["data", "classes", "train_split"])]
    pub object: Option<PathBuf>,
    /// Take the training split instead of the test split.
    #[arg(long)]
    pub train_split: bool,
    /// Only these classes (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub classes: Option<Vec<String>>,
    /// Points per cloud (default: 512, as the experiments and the shipped
    /// model; with --object 1,024, as `train --object`).
    #[arg(long, allow_negative_numbers = true)]
    pub points: Option<usize>,
    /// Number of pairs (0: one per shape).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub count: usize,
    /// Seed of preprocessing, template order and pairs.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// How sources are made from templates.
    #[command(flatten)]
    pub source: PairArgs,
    /// Resample: make each source from the shape's points the template did
    /// not keep (no shared points, as with a real sensor).
    #[arg(long)]
    pub resample: bool,
    /// Output file (JSON).
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `pcrnet eval`.
#[derive(Debug, Clone, Args)]
pub struct EvalArgs {
    /// A pair set written by `pcrnet pairs` or an experiment.
    #[arg(long)]
    pub pairs: PathBuf,
    /// The method.
    #[arg(long, value_enum)]
    pub method: MethodKind,
    /// Model and settings of the method.
    #[command(flatten)]
    pub options: MethodOptions,
    /// Register one pair at a time (for timing; default: all cores).
    #[arg(long)]
    pub sequential: bool,
    /// Also write the scores (summary and per pair) as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A method's model and settings on the command line (`pcrnet register`
/// and `pcrnet eval`).
#[derive(Debug, Clone, Args)]
pub struct MethodOptions {
    /// Model blob: int8 or f32 for device / pcrnet / ipcrnet, f32 for pointnetlk.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Network passes of device / ipcrnet (ipcrnet: 20; device: as the blob
    /// was trained, 1 for PCRNet), steps of pointnetlk (20) or iterations of
    /// icp (100).
    #[arg(long, allow_negative_numbers = true)]
    pub iterations: Option<usize>,
    /// Starting poses the device pipeline tries: 1 (the network's pose)
    /// up to 1 + the turns stored in the blob (default: `pcrnet-core`'s
    /// recommended 10, the network's pose and its half and quarter turns
    /// about the template's principal axes).
    #[arg(long, allow_negative_numbers = true)]
    pub hypotheses: Option<usize>,
    /// ICP iterations every hypothesis of the device pipeline gets before
    /// the two best go on.
    #[arg(long, allow_negative_numbers = true)]
    pub screen_iterations: Option<usize>,
    /// Most ICP iterations of the device pipeline in all (0: no refinement).
    #[arg(long, allow_negative_numbers = true)]
    pub icp_iterations: Option<usize>,
    /// What the device pipeline's ICP minimises.
    #[arg(long, value_enum)]
    pub metric: Option<super::methods::DeviceMetric>,
    /// Most source points the device pipeline scores and refines (every
    /// k-th point is used).
    #[arg(long, allow_negative_numbers = true)]
    pub max_points: Option<usize>,
    /// Most source points each network pass (and LK step) of the device
    /// pipeline encodes (every k-th point; default, or 0: the blob's own,
    /// 128 with a head, 256 for a PointNetLK blob).
    #[arg(long, allow_negative_numbers = true)]
    pub network_points: Option<usize>,
    /// Device ICP leaves out pairs farther apart than this, as a share of
    /// the template's size.
    #[arg(long, allow_negative_numbers = true)]
    pub icp_distance: Option<f32>,
    /// Device ICP stops once an update moves the pose by less than this
    /// (`||dT - I||_F`).
    #[arg(long, allow_negative_numbers = true)]
    pub icp_tolerance: Option<f32>,
    /// The device residual counts a point at most this far from the
    /// template, and the fitness counts points within it (a share of the
    /// template's size).
    #[arg(long, allow_negative_numbers = true)]
    pub inlier_distance: Option<f32>,
    /// The device pipeline calls a pose reliable when its relative plane
    /// residual is at most this (a share of the template's size). Without
    /// it: `register`, `track` and `register --scene` use the blob's verdict
    /// (calibrated by the template's residual floor when there is one),
    /// `eval` and the experiments 0.015.
    #[arg(long, allow_negative_numbers = true)]
    pub max_residual: Option<f32>,
    /// Template points the device pipeline stores when a template cloud is
    /// given in place of the blob's own (farthest-point subsampled, all of
    /// them when the cloud has fewer; 1 to 65535, default 512): its check
    /// and ICP run against these: more points refine finer, and a blob
    /// stores about 10 bytes of flash per point (point, normal, search grid).
    #[arg(long, allow_negative_numbers = true)]
    pub template_points: Option<usize>,
    /// PointNetLK steps of the device pipeline after its network passes
    /// (--method device; default 0: none, or for a model trained as
    /// PointNetLK, which has no head, as many as it was trained for).
    /// Needs a blob with PointNetLK's solver (`pcrnet export --lk`).
    #[arg(long, allow_negative_numbers = true)]
    pub lk_iterations: Option<usize>,
    /// Refine the network's pose with ICP.
    #[arg(long)]
    pub refine_icp: bool,
    /// i-PCRNet stop rule: stop once a pass moves the pose by less than
    /// this (`||dT - I||_F`; the paper: 1e-7).
    #[arg(long, allow_negative_numbers = true)]
    pub tolerance: Option<f32>,
}

impl MethodOptions {
    /// Refuses values no method can run with, naming the flag.
    pub fn check(&self) -> anyhow::Result<()> {
        let at_least_one = [
            ("--iterations", self.iterations),
            ("--hypotheses", self.hypotheses),
            ("--max-points", self.max_points),
            ("--network-points", self.network_points),
            ("--template-points", self.template_points),
        ];
        for (flag, v) in at_least_one {
            anyhow::ensure!(v != Some(0), "{flag} must be at least 1");
        }
        let above_zero = [
            ("--icp-distance", self.icp_distance),
            ("--inlier-distance", self.inlier_distance),
        ];
        for (flag, v) in above_zero {
            if let Some(d) = v {
                anyhow::ensure!(
                    d.is_finite() && d > 0.0,
                    "{flag} {d} must be a finite share of the template's size above 0"
                );
            }
        }
        let at_least_zero = [
            ("--tolerance", self.tolerance),
            ("--icp-tolerance", self.icp_tolerance),
            ("--max-residual", self.max_residual),
        ];
        for (flag, v) in at_least_zero {
            if let Some(t) = v {
                anyhow::ensure!(
                    t.is_finite() && t >= 0.0,
                    "{flag} {t} must be finite and at least 0"
                );
            }
        }
        Ok(())
    }

    /// What is wrong with running `blob` as `kind` with these options
    /// (see [`crate::methods::mode_mismatch`]), if anything.
    pub fn mode_warning(&self, kind: MethodKind, blob: Option<&[u8]>) -> Option<String> {
        let trained = crate::register::trained_passes(blob?).ok()?;
        crate::methods::mode_mismatch(kind, trained, self.iterations)
    }

    /// Refuses a `--hypotheses` the device pipeline cannot run in full:
    /// more than 1 + the template's turns (the blob's own, or
    /// [`pcrnet_train::template::PRINCIPAL_TURNS`] for a template file bound in
    /// its place, `bound`), which the pipeline would cut silently.
    pub fn check_hypotheses(
        &self,
        kind: MethodKind,
        blob: Option<&[u8]>,
        bound: bool,
    ) -> anyhow::Result<()> {
        let (Some(asked), MethodKind::Device) = (self.hypotheses, kind) else {
            return Ok(());
        };
        let turns = match blob {
            _ if bound => pcrnet_train::template::PRINCIPAL_TURNS,
            Some(blob) => match crate::register::template_turns(blob) {
                Ok(turns) => turns,
                // The method reports what is wrong with the blob.
                Err(_) => return Ok(()),
            },
            None => return Ok(()),
        };
        anyhow::ensure!(
            asked <= turns + 1,
            "--hypotheses {asked}: the template has {turns} turns, so the device tries 1 to {} starting poses (the network's pose, then it followed by each turn)",
            turns + 1
        );
        Ok(())
    }

    /// `kind` with these settings (the paper's where not given).
    pub fn method(&self, kind: MethodKind) -> Method {
        let mut m = Method::new(kind);
        m.iterations = self.iterations.unwrap_or(m.iterations);
        m.refine_icp = self.refine_icp;
        m.tolerance = self.tolerance.unwrap_or(m.tolerance);
        m.hypotheses = self.hypotheses.unwrap_or(m.hypotheses);
        m.icp_iterations = self.icp_iterations.unwrap_or(m.icp_iterations);
        m.screen_iterations = self.screen_iterations.unwrap_or(m.screen_iterations);
        m.max_points = self.max_points.unwrap_or(m.max_points);
        m.network_points = self.network_points.unwrap_or(m.network_points);
        m.metric = self.metric.unwrap_or(m.metric);
        m.icp_distance = self.icp_distance.unwrap_or(m.icp_distance);
        m.icp_tolerance = self.icp_tolerance.unwrap_or(m.icp_tolerance);
        m.inlier_distance = self.inlier_distance.unwrap_or(m.inlier_distance);
        m.max_residual = self.max_residual.unwrap_or(m.max_residual);
        m.template_points = self.template_points.unwrap_or(m.template_points);
        m.lk_iterations = self.lk_iterations.unwrap_or(m.lk_iterations);
        m
    }

    /// The model blob's bytes, when `--model` is given.
    pub fn read_model(&self) -> anyhow::Result<Option<Vec<u8>>> {
        self.model
            .as_ref()
            .map(|p| std::fs::read(p).with_context(|| format!("reading {}", p.display())))
            .transpose()
    }
}

/// Arguments of `pcrnet experiment`.
#[derive(Debug, Clone, Args)]
pub struct ExperimentArgs {
    /// Experiment name, or `all`.
    pub name: String,
    /// Data root holding `ModelNet10/` and `ModelNet40-airplane/`.
    #[arg(long)]
    pub data: PathBuf,
    /// Models, pair sets and per-pair scores.
    #[arg(long, default_value = "target/experiments")]
    pub work: PathBuf,
    /// Reports and plots.
    #[arg(long, default_value = "results")]
    pub results: PathBuf,
    /// Pairs per set.
    #[arg(long, default_value_t = 200, allow_negative_numbers = true)]
    pub pairs: usize,
    /// Seed of the pair sets.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
}

/// Arguments of `pcrnet results`.
#[derive(Debug, Clone, Args)]
pub struct ResultsArgs {
    /// Folder with the experiment reports.
    #[arg(long, default_value = "results")]
    pub results: PathBuf,
    /// The Markdown file to write (default: `RESULTS.md` beside the
    /// reports' folder, so that `--results /tmp/run` writes
    /// `/tmp/RESULTS.md`, never the repository's page).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl ResultsArgs {
    /// Where the page goes: `--out`, or `RESULTS.md` beside `--results`.
    pub fn out_path(&self) -> PathBuf {
        self.out.clone().unwrap_or_else(|| {
            self.results
                .parent()
                .unwrap_or(std::path::Path::new(""))
                .join("RESULTS.md")
        })
    }
}

/// Runs `pcrnet pairs`.
pub fn pairs(args: PairsArgs) -> anyhow::Result<()> {
    let shapes = match (&args.data, args.generated, &args.object) {
        (Some(root), ..) => Shapes::Folder {
            root: root.clone(),
            test_split: !args.train_split,
            classes: args.classes.clone(),
        },
        (None, Some(count), _) => Shapes::Generated { count },
        (None, None, Some(path)) => Shapes::Object { path: path.clone() },
        (None, None, None) => {
            anyhow::bail!("give --data FOLDER, --object FILE or --generated COUNT")
        }
    };
    let spec = PairSetSpec {
        shapes,
        points: args.points.unwrap_or(match args.object {
            Some(_) => pcrnet_train::cli::DEFAULT_POINTS,
            None => report::POINTS,
        }),
        sampling: Sampling::Fps,
        pairs: args.source.config(false)?,
        count: args.count,
        seed: args.seed,
        resample: args.resample,
    };
    let loaded = spec.load_shapes()?;
    let set = PairSet::generate(spec, &loaded);
    set.save(&args.out)?;
    eprintln!(
        "wrote {} pairs over {} shapes to {}",
        set.pairs.len(),
        loaded.len(),
        args.out.display()
    );
    Ok(())
}

/// Runs `pcrnet eval`.
pub fn eval(args: EvalArgs) -> anyhow::Result<()> {
    // What is wrong with the flags is said once, before any pair is read.
    let method = args.options.method(args.method);
    args.options.check()?;
    let blob = args.options.read_model()?;
    if method.needs_model() && blob.is_none() {
        return Err(super::methods::MethodError::NoModel(args.method).into());
    }
    // Every pair's template is bound in place of the blob's own.
    args.options
        .check_hypotheses(args.method, blob.as_deref(), true)?;
    if let Some(warning) = args.options.mode_warning(args.method, blob.as_deref()) {
        eprintln!("warning: {warning}");
    }
    let set = PairSet::load(&args.pairs)?;
    let pairs = set.materialise(&set.spec.load_shapes()?)?;
    let name = args
        .options
        .model
        .as_ref()
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    let model = blob.as_deref().map(|b| (name.as_str(), b));
    let s = super::score(&method, model, &pairs, !args.sequential)?;
    let m = &s.summary;
    println!(
        "{} on {} ({} pairs)",
        s.method,
        args.pairs.display(),
        m.count
    );
    let passes: Vec<f64> = s.pairs.iter().map(|p| p.iterations as f64).collect();
    let passes = pcrnet_train::metrics::Stats::of(&passes);
    println!(
        "iterations: mean {:.2}, median {:.1}, max {:.0}",
        passes.mean, passes.median, passes.max
    );
    println!(
        "rotation error (deg): mean {:.3}, median {:.3}, std {:.3}, max {:.3}",
        m.rotation_deg.mean, m.rotation_deg.median, m.rotation_deg.std, m.rotation_deg.max
    );
    println!(
        "translation error:    mean {:.4}, median {:.4}, std {:.4}, max {:.4}",
        m.translation.mean, m.translation.median, m.translation.std, m.translation.max
    );
    println!("AUC (0-180 deg): {:.4}", m.auc);
    if !s.failures.is_empty() {
        println!(
            "{} registration(s) failed and score as the identity pose:",
            s.failures.len()
        );
        for f in &s.failures {
            println!("  {f}");
        }
    }
    for x in &m.success {
        println!(
            "success (rot <= {}°, trans <= {}): {:.3}",
            x.rot_deg, x.trans, x.ratio
        );
    }
    let over_30 = s.pairs.iter().filter(|p| p.rot_deg > 30.0).count();
    println!(
        "rotation errors above 30°: {over_30} ({:.1}%)",
        100.0 * over_30 as f64 / m.count.max(1) as f64
    );
    if let Some(c) = &s.confidence {
        println!(
            "confidence ({} good below {}°, {} bad): plane residual AUROC {}; flagged unreliable: {:.1}% of bad, {:.1}% of good; {:.1}% of reliable ones are bad",
            c.good,
            c.good_below_deg,
            c.bad,
            c.auroc.map_or("n/a".into(), |a| format!("{a:.3}")),
            100.0 * c.bad_flagged,
            100.0 * c.good_flagged,
            100.0 * c.reliable_but_bad
        );
    }
    if let Some(t) = m.time_ms {
        println!(
            "time per registration: mean {:.2} ms, median {:.2} ms{}",
            t.mean,
            t.median,
            if args.sequential {
                ""
            } else {
                " (pairs ran in parallel; use --sequential for timing)"
            }
        );
    }
    if let Some(out) = &args.out {
        std::fs::write(out, serde_json::to_string_pretty(&s)?)
            .with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}

/// Runs `pcrnet experiment`.
pub fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let ctx = Context {
        data: args.data,
        work: args.work,
        results: args.results,
        pairs: args.pairs,
        seed: args.seed,
    };
    let names: Vec<&str> = if args.name == "all" {
        EXPERIMENTS.to_vec()
    } else {
        vec![args.name.as_str()]
    };
    let started = std::time::Instant::now();
    for (i, name) in names.iter().enumerate() {
        eprintln!(
            "experiment {}/{} {name} ({:.0} s so far)",
            i + 1,
            names.len(),
            started.elapsed().as_secs_f64()
        );
        let report = experiments::run_experiment(&ctx, name)?;
        eprintln!(
            "wrote {} and {} plot(s) in {:.0} s",
            ctx.results.join(format!("{name}.json")).display(),
            report.plots.len(),
            report.provenance.seconds
        );
    }
    Ok(())
}

/// Runs `pcrnet results`.
pub fn results(args: ResultsArgs) -> anyhow::Result<()> {
    let md = experiments::render_results(&args.results)?;
    let out = args.out_path();
    std::fs::write(&out, md).with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_results_page_goes_beside_its_reports() {
        let page = |results: &str, out: Option<&str>| {
            ResultsArgs {
                results: results.into(),
                out: out.map(PathBuf::from),
            }
            .out_path()
        };
        assert_eq!(page("results", None), PathBuf::from("RESULTS.md"));
        assert_eq!(page("/tmp/run", None), PathBuf::from("/tmp/RESULTS.md"));
        assert_eq!(page("/tmp/run", Some("x.md")), PathBuf::from("x.md"));
    }
}
