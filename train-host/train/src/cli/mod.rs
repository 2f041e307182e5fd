//! The `pcrnet train` subcommand (arguments and driver), the argument
//! parsers `pairs` and `eval` share, and the blob-writing subcommands
//! (`export`, `upgrade`: [`export`], [`upgrade`]).

mod blobs;
mod object;
mod pairs;
pub use blobs::{ExportArgs, UpgradeArgs, export, parse_axis, upgrade};
use blobs::{load_template, trained_for, with_up, write_blobs};
pub use pairs::{PairArgs, parse_fraction, parse_sigma};

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};

use super::{
    CHECKPOINT_FILE, Checkpoint, Dataset, LossKind, ModelKind, RunOptions, Sampling, Schedule,
    Split, TrainConfig, Trainer, data,
};
use crate::template::{DEFAULT_TEMPLATE_POINTS, Reference};
use crate::{EMBEDDED_ENCODER, EMBEDDED_HEAD};

/// Network kind on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// Single pass.
    Pcrnet,
    /// Iterative (see --iterations).
    Ipcrnet,
    /// PointNetLK: the encoder trained through --iterations Lucas-Kanade
    /// iterations (the PointNetLK reference uses 10). Checkpoints only:
    /// no blobs yet.
    Pointnetlk,
}

/// Loss on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LossArg {
    /// Chamfer distance (the paper's).
    Chamfer,
    /// Frobenius distance of the 4x4 poses.
    Pose,
}

/// Schedule on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ScheduleArg {
    /// Cosine to 1% of --lr.
    Cosine,
    /// Halve every --step-epochs epochs.
    Step,
    /// Constant --lr.
    Constant,
}

/// Subsampling on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SamplingArg {
    /// Farthest point sampling.
    Fps,
    /// Random subset.
    Random,
}

/// Arguments of `pcrnet train`.
#[derive(Debug, Clone, Args)]
pub struct TrainArgs {
    /// ModelNet-style root (`<root>/<class>/{train,test}/*.pcd`, or
    /// `<root>/{train,test}/*` for one class named after the root); the
    /// test split is the validation set. Repeat it to train on several
    /// roots at once (`--classes` then names classes of any of them).
    #[arg(long)]
    pub data: Vec<PathBuf>,
    /// Train on this many generated shapes (validation: a quarter as many),
    /// alone or added to the --data roots.
    #[arg(long, conflicts_with = "object", allow_negative_numbers = true)]
    pub generated: Option<usize>,
    /// Train for one object of your own: a point cloud file, or an OFF mesh
    /// (sampled by area), in any unit. It is also the template (unless
    /// --template), so the blobs record its frame; validation draws other
    /// poses of it. Defaults for it: 64 steps per epoch, 64 validation pairs.
    #[arg(long, conflicts_with_all = ["data", "single_model", "classes"])]
    pub object: Option<PathBuf>,
    /// Only these classes (comma-separated): single- or few-category training.
    #[arg(long, value_delimiter = ',')]
    pub classes: Option<Vec<String>>,
    /// Train (and validate) on the training shape of this index only.
    #[arg(long, allow_negative_numbers = true)]
    pub single_model: Option<usize>,
    /// `embedded`, `paper` (PCRNet head), `ipcrnet` (paper encoder,
    /// i-PCRNet head) or custom widths `E1,E2,...:H1,H2,...`.
    #[arg(long, default_value = "embedded")]
    pub arch: String,
    /// Single-pass or iterative network.
    #[arg(long, value_enum, default_value_t = ModelArg::Pcrnet)]
    pub model: ModelArg,
    /// i-PCRNet passes, or PointNetLK's Lucas-Kanade iterations.
    #[arg(long, default_value_t = 8, allow_negative_numbers = true)]
    pub iterations: usize,
    /// Points per cloud.
    #[arg(long, default_value_t = DEFAULT_POINTS, allow_negative_numbers = true)]
    pub points: usize,
    /// How clouds are reduced to --points.
    #[arg(long, value_enum, default_value_t = SamplingArg::Fps)]
    pub sampling: SamplingArg,
    /// Pairs per step.
    #[arg(long, default_value_t = 32, allow_negative_numbers = true)]
    pub batch: usize,
    /// Epochs.
    #[arg(long, default_value_t = 10, allow_negative_numbers = true)]
    pub epochs: usize,
    /// Steps per epoch (default: training shapes / batch; 64 with --object).
    #[arg(long, allow_negative_numbers = true)]
    pub steps_per_epoch: Option<usize>,
    /// Base learning rate (Adam).
    #[arg(long, default_value_t = 1e-3, allow_negative_numbers = true)]
    pub lr: f32,
    /// Learning-rate schedule.
    #[arg(long, value_enum, default_value_t = ScheduleArg::Cosine)]
    pub schedule: ScheduleArg,
    /// Epochs between halvings with --schedule step.
    #[arg(long, default_value_t = 10, allow_negative_numbers = true)]
    pub step_epochs: usize,
    /// Training loss.
    #[arg(long, value_enum, default_value_t = LossArg::Chamfer)]
    pub loss: LossArg,
    /// Seed of weights and pairs.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// How sources are made from templates.
    #[command(flatten)]
    pub pairs: PairArgs,
    /// Make each source from the shape's other points (those the
    /// reduction to --points did not keep), none shared with the template,
    /// as a sensor samples a surface anew; as `pcrnet pairs --resample`.
    /// Needs shapes with more points than --points.
    #[arg(long)]
    pub resample: bool,
    /// Feed the network uncentred sources (default: sources centred on
    /// their centroid, as the reference implementation; see `train::data`).
    #[arg(long)]
    pub no_centre: bool,
    /// Clip the gradient's global norm.
    #[arg(long, allow_negative_numbers = true)]
    pub clip: Option<f32>,
    /// Validation pairs (0: one per validation shape; 64 with --object).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub val_pairs: usize,
    /// Also checkpoint every this many steps (0: at epoch ends only).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub checkpoint_every: usize,
    /// Output folder: checkpoint, log, config, blobs.
    #[arg(long)]
    pub out: PathBuf,
    /// Resume from `<out>/checkpoint.bin` (its configuration wins).
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
    /// Start afresh in an --out folder that holds an earlier run, replacing
    /// its checkpoint and log (without it, or --resume, such a folder is
    /// refused: two runs would mix in one log).
    #[arg(long)]
    pub force: bool,
    /// Stop after this many steps and report step times (timing runs; no export).
    #[arg(long, allow_negative_numbers = true)]
    pub max_steps: Option<usize>,
    /// No effect: training always ends by exporting both blobs (f32 and
    /// int8), as `pcrnet export` does. Accepted so that commands recorded
    /// in RESULTS.md before that still run.
    #[arg(long, hide = true)]
    pub export: bool,
    /// Template embedded in the blobs (default: the --object, or the first
    /// training shape).
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// Template points stored in the blob for checking and refining poses
    /// on the device (about 10 bytes of flash each: 6 for the point, 3 for
    /// its normal, about 1 for the search grid).
    #[arg(long, default_value_t = DEFAULT_TEMPLATE_POINTS, allow_negative_numbers = true)]
    pub template_points: usize,
    /// The template's up axis (x, y, z, -x, -y or -z, its file's axes: the
    /// axis pointing away from the surface the object rests on), stored in
    /// both blobs: `register --scene` then finds the object standing on
    /// the plane in any yaw without `--up`.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_axis)]
    pub up: Option<[f32; 3]>,
    /// No progress bars.
    #[arg(long)]
    pub no_progress: bool,
}

/// Points per cloud of `train` unless given (and of `pairs --object`, so
/// that an object's test pairs match its training).
pub const DEFAULT_POINTS: usize = 1024;

/// Steps per epoch of `train --object` unless given: one shape makes
/// `shapes / batch` a single step.
const OBJECT_STEPS: usize = 64;

/// Validation pairs of `train --object` unless given (other poses of the
/// same object).
const OBJECT_VAL_PAIRS: usize = 64;

/// Parses `embedded`, `paper`, `ipcrnet` or `E1,E2:H1,H2` into widths.
pub fn parse_arch(s: &str) -> anyhow::Result<(Vec<u16>, Vec<u16>)> {
    use pcrnet_core::arch::{IPCRNET_HEAD, PAPER_ENCODER, PCRNET_HEAD};
    Ok(match s {
        "embedded" => (EMBEDDED_ENCODER.to_vec(), EMBEDDED_HEAD.to_vec()),
        "paper" => (PAPER_ENCODER.to_vec(), PCRNET_HEAD.to_vec()),
        "ipcrnet" => (PAPER_ENCODER.to_vec(), IPCRNET_HEAD.to_vec()),
        custom => {
            let (e, h) = custom.split_once(':').unwrap_or((custom, ""));
            let widths = |t: &str| -> anyhow::Result<Vec<u16>> {
                t.split(',')
                    .filter(|x| !x.trim().is_empty())
                    .map(|x| {
                        x.trim()
                            .parse::<u16>()
                            .with_context(|| format!("width {x:?}"))
                    })
                    .collect()
            };
            let (e, h) = (widths(e)?, widths(h)?);
            pcrnet_core::Arch::new(&e, &h)
                .map_err(|e| anyhow::anyhow!("architecture {custom:?}: {e}"))?;
            (e, h)
        }
    })
}

fn config_from(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    let (encoder, head) = parse_arch(&args.arch)?;
    let config = TrainConfig {
        encoder,
        head,
        model: match args.model {
            ModelArg::Pcrnet => ModelKind::Pcrnet,
            ModelArg::Ipcrnet => ModelKind::Ipcrnet {
                iterations: args.iterations,
            },
            ModelArg::Pointnetlk => ModelKind::PointNetLk {
                iterations: args.iterations,
            },
        },
        loss: match args.loss {
            LossArg::Chamfer => LossKind::Chamfer,
            LossArg::Pose => LossKind::Pose,
        },
        batch: args.batch,
        epochs: args.epochs,
        steps_per_epoch: args
            .steps_per_epoch
            .or(args.object.as_ref().map(|_| OBJECT_STEPS)),
        lr: args.lr,
        schedule: match args.schedule {
            ScheduleArg::Cosine => Schedule::Cosine { min_factor: 0.01 },
            ScheduleArg::Step => Schedule::Step {
                every_epochs: args.step_epochs,
                gamma: 0.5,
            },
            ScheduleArg::Constant => Schedule::Constant,
        },
        seed: args.seed,
        pairs: args.pairs.config(!args.no_centre)?,
        clip_norm: args.clip,
        checkpoint_every: args.checkpoint_every,
        val_pairs: match (args.val_pairs, &args.object) {
            (0, Some(_)) => OBJECT_VAL_PAIRS,
            (n, _) => n,
        },
        points: args.points,
        sampling: sampling(args.sampling),
        resample: args.resample,
    };
    if !(config.lr.is_finite() && config.lr > 0.0) {
        bail!("--lr must be a finite number > 0 (got {})", config.lr);
    }
    if config.epochs == 0 || config.batch == 0 || config.points == 0 {
        bail!("--epochs, --batch and --points must be at least 1");
    }
    if config.steps_per_epoch == Some(0) {
        bail!("--steps-per-epoch must be at least 1");
    }
    Ok(config)
}

fn sampling(a: SamplingArg) -> Sampling {
    match a {
        SamplingArg::Fps => Sampling::Fps,
        SamplingArg::Random => Sampling::Random,
    }
}

fn load_data(args: &TrainArgs, seed: u64) -> anyhow::Result<(Dataset, Dataset)> {
    let (mut train, mut val) = if let Some(object) = &args.object {
        object::check_object(object, args.points)?;
        let train = Dataset::object(object, args.points, sampling(args.sampling), seed)?;
        (train.clone(), train)
    } else {
        let s = sampling(args.sampling);
        let classes = args.classes.as_deref();
        let mut sets: Vec<(Dataset, Dataset)> = Vec::new();
        for (i, root) in args.data.iter().enumerate() {
            // The first root keeps the seed of a one-root run.
            let seed = match i {
                0 => seed,
                _ => data::mix_seed(seed, 0xDA7A, i as u64),
            };
            let train = Dataset::load_modelnet(root, Split::Train, classes, args.points, s, seed)?;
            let val = Dataset::load_modelnet(root, Split::Test, classes, args.points, s, seed ^ 1)?;
            sets.push((train, val));
        }
        if let Some(n) = args.generated {
            let train = Dataset::generated(n, args.points, seed);
            let val = Dataset::generated(n.div_ceil(4), args.points, seed ^ 0xABCD);
            sets.push((train, val));
        }
        let mut sets = sets.into_iter();
        let Some((mut train, mut val)) = sets.next() else {
            bail!("give --data PATH (repeatable), --generated COUNT, or --object FILE");
        };
        for (t, v) in sets {
            train.append(t);
            val.append(v);
        }
        (train, val)
    };
    if let Some(i) = args.single_model {
        if i >= train.len() {
            bail!(
                "--single-model {i}: the training set has {} shapes (0..{})",
                train.len(),
                train.len()
            );
        }
        train = train.single_model(i);
        val = train.clone();
    }
    Ok((train, val))
}

/// Runs `pcrnet train`.
pub fn train(args: TrainArgs) -> anyhow::Result<()> {
    let config = config_from(&args)?;
    std::fs::create_dir_all(&args.out)?;
    let ck_path = args.out.join(CHECKPOINT_FILE);
    let log_path = args.out.join(crate::LOG_FILE);
    let earlier = ck_path.exists() || log_path.exists();
    if earlier && !args.resume {
        anyhow::ensure!(
            args.force,
            "{} holds an earlier run (checkpoint or log): pass --resume to continue it, --force to replace it, or another --out",
            args.out.display()
        );
        for p in [&ck_path, &log_path] {
            if p.exists() {
                std::fs::remove_file(p).with_context(|| format!("removing {}", p.display()))?;
            }
        }
    }
    anyhow::ensure!(
        !args.resume || ck_path.exists() || !log_path.exists(),
        "{} has a log but no checkpoint to resume from: pass --force to start afresh",
        args.out.display()
    );
    let resume = args.resume && ck_path.exists();
    if args.resume && !resume {
        eprintln!("no checkpoint in {}: starting afresh", args.out.display());
    }
    // A resumed run loads its data as the checkpoint says.
    let (seed, data_args) = if resume {
        let ck = Checkpoint::load(&ck_path)?;
        let mut a = args.clone();
        a.points = ck.config.points;
        a.sampling = match ck.config.sampling {
            Sampling::Fps => SamplingArg::Fps,
            Sampling::Random => SamplingArg::Random,
        };
        (ck.config.seed, a)
    } else {
        (config.seed, args.clone())
    };
    let t0 = std::time::Instant::now();
    let (train, val) = load_data(&data_args, seed)?;
    eprintln!(
        "data: {} training shapes, {} validation shapes, {} points each ({:.1} s)",
        train.len(),
        val.len(),
        train.points,
        t0.elapsed().as_secs_f64()
    );
    let mut trainer = if resume {
        let ck = Checkpoint::load(&ck_path)?;
        if ck.config != config {
            eprintln!(
                "resuming with the checkpoint's configuration (command-line hyperparameters ignored)"
            );
        }
        eprintln!(
            "resuming at epoch {} step {} (global step {})",
            ck.progress.epoch, ck.progress.step_in_epoch, ck.progress.global_step
        );
        Trainer::from_checkpoint(ck, train, val)?
    } else {
        Trainer::new(config, train, val)?
    };
    crate::checkpoint::write_atomic(
        &args.out.join("config.json"),
        serde_json::to_string_pretty(&trainer.config)?.as_bytes(),
    )?;
    eprintln!(
        "arch {:?} / {:?}, {} parameters, {:?}, {:?} loss, batch {}, {} steps/epoch x {} epochs",
        trainer.config.encoder,
        trainer.config.head,
        trainer.params.arch.parameters(),
        trainer.config.model,
        trainer.config.loss,
        trainer.config.batch,
        trainer.steps_per_epoch(),
        trainer.config.epochs
    );
    let epochs = trainer.config.epochs;
    let summary = trainer.run_with(
        &RunOptions {
            out_dir: Some(args.out.clone()),
            progress: !args.no_progress,
            max_steps: args.max_steps,
        },
        // Each epoch as it ends, with an estimate of the time left from
        // this epoch's duration.
        |e| {
            let left = e.seconds * (epochs.saturating_sub(e.epoch + 1)) as f64;
            eprintln!(
                "epoch {:>3}/{epochs}: loss {:.5}  lr {:.2e}  val rot {:.2} deg (median {:.2})  trans {:.4} (median {:.4})  {:.0} s, about {:.0} s left",
                e.epoch + 1,
                e.train_loss,
                e.lr,
                e.val.rotation_deg.mean,
                e.val.rotation_deg.median,
                e.val.translation.mean,
                e.val.translation.median,
                e.seconds,
                left
            );
        },
    )?;
    let st = &summary.step_seconds;
    if st.len() > 1 {
        let rest = &st[1..];
        let mean = rest.iter().sum::<f64>() / rest.len() as f64;
        let min = rest.iter().copied().fold(f64::INFINITY, f64::min);
        eprintln!(
            "step time: first {:.3} s, then mean {:.3} s, min {:.3} s over {} steps",
            st[0],
            mean,
            min,
            rest.len()
        );
    }
    if !trainer.finished() {
        eprintln!("stopped before the end (--max-steps): no export");
        return Ok(());
    }
    let trained = trained_for(&trainer.config, false);
    let reference = match args.template.as_ref().or(args.object.as_ref()) {
        Some(p) => load_template(p, trainer.train_data().points, args.template_points, seed)?,
        None => Reference::new(&trainer.train_data().clouds[0], args.template_points)?,
    };
    let reference = with_up(reference, args.up)?;
    // Both blobs, as `pcrnet export` writes them.
    write_blobs(
        &trainer.params,
        &reference,
        &trainer.config.pairs,
        trainer.config.seed,
        trained,
        &args.out,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 10, item 16: `--noise` means the same in `train` as in
    /// `pairs` (a fixed sigma, or a range each pair draws from).
    #[test]
    fn train_noise_means_what_pairs_noise_means() {
        #[derive(clap::Parser)]
        struct Cmd {
            #[command(flatten)]
            args: TrainArgs,
        }
        let noise = |extra: &[&str]| {
            let argv = ["train", "--generated", "4", "--out", "x"];
            let cmd = <Cmd as clap::Parser>::try_parse_from(argv.iter().chain(extra)).unwrap();
            config_from(&cmd.args).unwrap().pairs.noise
        };
        assert_eq!(noise(&[]), None);
        assert_eq!(noise(&["--noise"]), Some([0.0, 0.04]));
        assert_eq!(noise(&["--noise", "0.02"]), Some([0.02, 0.02]));
        assert_eq!(noise(&["--noise", "0.01,0.03"]), Some([0.01, 0.03]));
    }
}
