//! The training loop: [`Trainer`] over a [`TrainConfig`], its epochs,
//! checkpoints and JSON-lines log (see the crate docs for the design).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use pcrnet_core::Arch;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::F32Params;
use crate::adam::{Adam, Schedule};
use crate::checkpoint::{Checkpoint, CheckpointError, Progress};
use crate::data::{PairConfig, Sampling};
use crate::dataset::Dataset;
use crate::loss::LossKind;
use crate::metrics::{Summary, rotation_error_deg, translation_error};
use crate::model::{Batch, ModelKind};
use crate::{adam, data, forward};

/// Scale applied to the initial output-layer weights (see the module docs).
pub const OUTPUT_INIT_SCALE: f32 = 0.01;

/// Checkpoint file name inside a run's output folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";
/// Log file name inside a run's output folder (JSON lines, one per epoch).
pub const LOG_FILE: &str = "log.jsonl";

/// Everything that defines a run (saved in checkpoints).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Encoder widths.
    pub encoder: Vec<u16>,
    /// Hidden head widths.
    pub head: Vec<u16>,
    /// PCRNet or i-PCRNet.
    pub model: ModelKind,
    /// Training loss.
    pub loss: LossKind,
    /// Pairs per step.
    pub batch: usize,
    /// Epochs to run.
    pub epochs: usize,
    /// Steps per epoch (default: training shapes / batch, at least 1).
    pub steps_per_epoch: Option<usize>,
    /// Base learning rate.
    pub lr: f32,
    /// Learning-rate schedule.
    pub schedule: Schedule,
    /// Seed of the initial weights and of every pair.
    pub seed: u64,
    /// How sources are made.
    pub pairs: PairConfig,
    /// Clip the gradient's global norm to this (none by default).
    pub clip_norm: Option<f32>,
    /// Also checkpoint every this many steps (0: at epoch ends only).
    pub checkpoint_every: usize,
    /// Validation pairs (0: one per validation shape).
    pub val_pairs: usize,
    /// Points per cloud the data was reduced to (recorded so that export
    /// and resume reduce clouds the same way).
    pub points: usize,
    /// How clouds were reduced to `points`.
    pub sampling: Sampling,
    /// Make each source from the shape's other points, none shared with
    /// the template ([`Dataset::source_points`]), in training and
    /// validation pairs alike.
    pub resample: bool,
}

impl Default for TrainConfig {
    /// Embedded architecture, PCRNet, Chamfer, batch 32, 10 epochs, Adam
    /// 1e-3 with cosine decay to 1e-5, seed 1, the paper's pairs.
    fn default() -> Self {
        TrainConfig {
            encoder: crate::EMBEDDED_ENCODER.to_vec(),
            head: crate::EMBEDDED_HEAD.to_vec(),
            model: ModelKind::Pcrnet,
            loss: LossKind::Chamfer,
            batch: 32,
            epochs: 10,
            steps_per_epoch: None,
            lr: 1e-3,
            schedule: Schedule::Cosine { min_factor: 0.01 },
            seed: 1,
            pairs: PairConfig::default(),
            clip_norm: None,
            checkpoint_every: 0,
            val_pairs: 0,
            points: 1024,
            sampling: Sampling::Fps,
            resample: false,
        }
    }
}

impl TrainConfig {
    /// The network shape.
    pub fn arch(&self) -> pcrnet_core::Result<Arch> {
        Arch::new(&self.encoder, &self.head)
    }
}

/// With `resample`, every training and validation shape must have other
/// points to draw sources from.
fn check_resample(resample: bool, train: &Dataset, val: &Dataset) -> Result<(), TrainError> {
    match (resample, train.cannot_resample().or(val.cannot_resample())) {
        (true, Some(name)) => Err(TrainError::NothingToResample(name.to_string())),
        _ => Ok(()),
    }
}

/// Initial parameters of a run (see the module docs).
pub fn initial_params(arch: Arch, seed: u64) -> F32Params {
    let mut p = F32Params::init(arch, seed);
    if let Some((w, b)) = p.layers.last_mut() {
        for v in w.iter_mut() {
            *v *= OUTPUT_INIT_SCALE;
        }
        b[0] = 1.0;
    }
    p
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepStats {
    /// Mean loss of the batch.
    pub loss: f32,
    /// Learning rate used.
    pub lr: f32,
    /// Gradient norm before clipping.
    pub grad_norm: f64,
}

/// One line of the training log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochLog {
    /// Epoch (0-based).
    pub epoch: usize,
    /// Steps done after this epoch.
    pub global_step: usize,
    /// Learning rate of the epoch's last step.
    pub lr: f32,
    /// Mean training loss over the epoch.
    pub train_loss: f64,
    /// Validation errors.
    pub val: Summary,
    /// Wall time of the epoch's steps and validation, seconds.
    pub seconds: f64,
}

/// How [`Trainer::run`] behaves.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Where checkpoints and the log go (nothing written when `None`).
    pub out_dir: Option<PathBuf>,
    /// Show progress bars.
    pub progress: bool,
    /// Stop after this many steps of this call (for timing and tests).
    pub max_steps: Option<usize>,
}

/// What [`Trainer::run`] did.
#[derive(Debug, Clone, Default)]
pub struct RunSummary {
    /// Wall time of every step, seconds.
    pub step_seconds: Vec<f64>,
    /// Log lines of the epochs finished.
    pub epochs: Vec<EpochLog>,
}

/// A training run: data, parameters, optimiser and position.
#[derive(Debug, Clone)]
pub struct Trainer {
    /// The configuration.
    pub config: TrainConfig,
    /// Current parameters.
    pub params: F32Params,
    /// Optimiser state.
    pub adam: Adam,
    /// Position in the run.
    pub progress: Progress,
    train: Dataset,
    val: Dataset,
}

/// Why a run could not be set up or written.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// Invalid architecture.
    #[error(transparent)]
    Arch(#[from] pcrnet_core::Error),
    /// No training shape.
    #[error("the training set is empty")]
    NoData,
    /// The batch size is 0.
    #[error("batch size must be at least 1")]
    ZeroBatch,
    /// `resample` is on but a shape has no other points to draw sources from.
    #[error(
        "{0}: no points left to resample sources from (--resample needs shapes with more points than --points; lower --points)"
    )]
    NothingToResample(String),
    /// The checkpoint's data set or configuration does not fit.
    #[error("checkpoint mismatch: {0}")]
    Mismatch(String),
    /// Checkpoint error.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// Writing the log failed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
}

impl Trainer {
    /// A fresh run. `val` may be empty (validation is then skipped).
    pub fn new(config: TrainConfig, train: Dataset, val: Dataset) -> Result<Self, TrainError> {
        let arch = config.arch()?;
        if train.is_empty() {
            return Err(TrainError::NoData);
        }
        if config.batch == 0 {
            return Err(TrainError::ZeroBatch);
        }
        check_resample(config.resample, &train, &val)?;
        let params = initial_params(arch, config.seed);
        let adam = Adam::new(&params);
        Ok(Trainer {
            config,
            params,
            adam,
            progress: Progress::default(),
            train,
            val,
        })
    }

    /// Resumes from a checkpoint with the same data.
    pub fn from_checkpoint(
        ck: Checkpoint,
        train: Dataset,
        val: Dataset,
    ) -> Result<Self, TrainError> {
        if train.is_empty() {
            return Err(TrainError::NoData);
        }
        if ck.config.arch()? != ck.arch {
            return Err(TrainError::Mismatch(
                "architecture differs from the configuration".into(),
            ));
        }
        check_resample(ck.config.resample, &train, &val)?;
        let params = ck.params();
        Ok(Trainer {
            config: ck.config,
            params,
            adam: ck.adam,
            progress: ck.progress,
            train,
            val,
        })
    }

    /// The current state as a checkpoint.
    pub fn checkpoint(&self) -> Checkpoint {
        Checkpoint {
            config: self.config.clone(),
            arch: self.params.arch.clone(),
            layers: self.params.layers.clone(),
            adam: self.adam.clone(),
            progress: self.progress,
        }
    }

    /// The training shapes.
    pub fn train_data(&self) -> &Dataset {
        &self.train
    }

    /// Steps per epoch.
    pub fn steps_per_epoch(&self) -> usize {
        self.config
            .steps_per_epoch
            .unwrap_or(self.train.len() / self.config.batch)
            .max(1)
    }

    /// Steps of the whole run.
    pub fn total_steps(&self) -> usize {
        self.steps_per_epoch() * self.config.epochs
    }

    /// Whether every epoch is done.
    pub fn finished(&self) -> bool {
        self.progress.epoch >= self.config.epochs
    }

    /// Learning rate of the next step.
    pub fn learning_rate(&self) -> f32 {
        self.config.schedule.rate(
            self.config.lr,
            self.progress.global_step,
            self.steps_per_epoch(),
            self.total_steps(),
        )
    }

    /// The batch of step `step` of epoch `epoch`: shapes in a per-epoch
    /// seeded order, pair seeds from (seed, epoch, slot).
    pub fn batch_at(&self, epoch: usize, step: usize) -> Batch {
        let b = self.config.batch;
        let mut order: Vec<usize> = (0..self.train.len()).collect();
        let mut rng =
            ChaCha8Rng::seed_from_u64(data::mix_seed(self.config.seed, 0x5EED, epoch as u64));
        order.shuffle(&mut rng);
        let slots: Vec<usize> = (step * b..(step + 1) * b).collect();
        let shapes: Vec<usize> = slots.iter().map(|&s| order[s % order.len()]).collect();
        let seeds: Vec<u64> = slots
            .iter()
            .map(|&s| data::mix_seed(self.config.seed, epoch as u64 + 1, s as u64))
            .collect();
        self.train
            .batch(&shapes, &seeds, &self.config.pairs, self.config.resample)
    }

    /// One optimisation step at the current position; advances the position
    /// (not past the end of the epoch: [`Trainer::end_epoch`] does that).
    pub fn step(&mut self) -> StepStats {
        let batch = self.batch_at(self.progress.epoch, self.progress.step_in_epoch);
        let lr = self.learning_rate();
        let mut out =
            forward::loss_and_grad(&self.params, self.config.model, self.config.loss, &batch);
        let grad_norm = match self.config.clip_norm {
            Some(c) => adam::clip_grad_norm(&mut out.grads, c),
            None => adam::grad_norm(&out.grads),
        };
        self.adam.update(&mut self.params, &out.grads, lr);
        self.progress.step_in_epoch += 1;
        self.progress.global_step += 1;
        self.progress.loss_sum += out.loss as f64;
        StepStats {
            loss: out.loss,
            lr,
            grad_norm,
        }
    }

    /// The fixed validation pairs (same for every epoch).
    pub fn validation_batches(&self) -> Vec<Batch> {
        if self.val.is_empty() {
            return Vec::new();
        }
        let count = if self.config.val_pairs == 0 {
            self.val.len()
        } else {
            self.config.val_pairs
        };
        let b = self.config.batch;
        (0..count)
            .step_by(b)
            .map(|start| {
                let idx: Vec<usize> = (start..(start + b).min(count)).collect();
                let shapes: Vec<usize> = idx.iter().map(|&i| i % self.val.len()).collect();
                let seeds: Vec<u64> = idx
                    .iter()
                    .map(|&i| data::mix_seed(self.config.seed, u64::MAX, i as u64))
                    .collect();
                self.val
                    .batch(&shapes, &seeds, &self.config.pairs, self.config.resample)
            })
            .collect()
    }

    /// Rotation and translation errors on the validation pairs.
    pub fn validate(&self) -> Summary {
        evaluate(&self.params, self.config.model, &self.validation_batches())
    }

    /// Closes the epoch: validation, log line, next epoch.
    pub fn end_epoch(&mut self, started: Instant) -> EpochLog {
        let val = self.validate();
        let steps = self.progress.step_in_epoch.max(1);
        let log = EpochLog {
            epoch: self.progress.epoch,
            global_step: self.progress.global_step,
            lr: self.config.schedule.rate(
                self.config.lr,
                self.progress.global_step.saturating_sub(1),
                self.steps_per_epoch(),
                self.total_steps(),
            ),
            train_loss: self.progress.loss_sum / steps as f64,
            val,
            seconds: started.elapsed().as_secs_f64(),
        };
        self.progress.epoch += 1;
        self.progress.step_in_epoch = 0;
        self.progress.loss_sum = 0.0;
        log
    }

    /// Runs until every epoch is done (or `max_steps`), checkpointing into
    /// and logging to `out_dir` when given.
    pub fn run(&mut self, opts: &RunOptions) -> Result<RunSummary, TrainError> {
        self.run_with(opts, |_| {})
    }

    /// [`Trainer::run`], calling `on_epoch` with each epoch's log line as
    /// soon as the epoch is logged and checkpointed.
    pub fn run_with(
        &mut self,
        opts: &RunOptions,
        mut on_epoch: impl FnMut(&EpochLog),
    ) -> Result<RunSummary, TrainError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |error| TrainError::Io { path, error }
        };
        if let Some(dir) = &opts.out_dir {
            std::fs::create_dir_all(dir).map_err(io(dir))?;
        }
        let save = |t: &Trainer| -> Result<(), TrainError> {
            if let Some(dir) = &opts.out_dir {
                t.checkpoint().save(&dir.join(CHECKPOINT_FILE))?;
            }
            Ok(())
        };
        let mut summary = RunSummary::default();
        let spe = self.steps_per_epoch();
        while !self.finished() {
            let started = Instant::now();
            let epoch = format!("epoch {}/{}", self.progress.epoch + 1, self.config.epochs);
            let bar = opts.progress.then(|| {
                let bar = pcrnet_io::progress::Progress::bar(spe as u64, epoch.as_str());
                bar.inc(self.progress.step_in_epoch as u64);
                bar
            });
            while self.progress.step_in_epoch < spe {
                if opts
                    .max_steps
                    .is_some_and(|m| summary.step_seconds.len() >= m)
                {
                    return Ok(summary);
                }
                let t0 = Instant::now();
                let s = self.step();
                summary.step_seconds.push(t0.elapsed().as_secs_f64());
                if let Some(bar) = &bar {
                    bar.inc(1);
                    bar.set_message(format!("{epoch} loss {:.5} lr {:.2e}", s.loss, s.lr));
                }
                let every = self.config.checkpoint_every;
                if every > 0 && self.progress.global_step.is_multiple_of(every) {
                    save(self)?;
                }
            }
            drop(bar);
            let log = self.end_epoch(started);
            if let Some(dir) = &opts.out_dir {
                let path = dir.join(LOG_FILE);
                let mut f = std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(&path)
                    .map_err(io(&path))?;
                let line = serde_json::to_string(&log).unwrap_or_default();
                writeln!(f, "{line}").map_err(io(&path))?;
            }
            save(self)?;
            on_epoch(&log);
            summary.epochs.push(log);
        }
        Ok(summary)
    }
}

/// Rotation and translation errors of a model on batches of pairs (the
/// translation of the pose between the clouds as made; see [`crate::metrics`]).
pub fn evaluate(params: &F32Params, model: ModelKind, batches: &[Batch]) -> Summary {
    let mut rot = Vec::new();
    let mut trans = Vec::new();
    for b in batches {
        let poses = forward::predict(params, model, &b.template, &b.source, b.size, b.points);
        for (i, (r, t)) in poses.iter().enumerate() {
            // Translations of the poses between the clouds as made, not
            // of the centred frame the network sees.
            let c = &b.centroids[i];
            let t_est = data::uncentre_translation(r, t, c);
            let t_gt = data::uncentre_translation(&b.r_gt[i], &b.t_gt[i], c);
            rot.push(rotation_error_deg(r, &b.r_gt[i]));
            trans.push(translation_error(&t_est, &t_gt));
        }
    }
    Summary::of(&rot, &trans, None)
}
