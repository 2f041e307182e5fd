//! # pcrnet-train
//!
//! Training PCRNet and i-PCRNet on the host, and everything a model blob is
//! made of: the f32 parameters ([`net`]), the template a blob records
//! ([`template`]), post-training quantization to `pcrnet-core`'s int8
//! format ([`quantize()`]), export ([`export`]), upgrading old blobs
//! ([`upgrade`]) and describing one ([`inspect`]); with the rigid-body
//! geometry ([`geometry`]), generated shapes ([`shapes`]) and the pose
//! metrics ([`metrics`]) training reports. The `train`, `export` and
//! `upgrade` commands' arguments and runs are [`cli`].
//!
//! The forward pass is `pcrnet-core`'s own f32 path ([`pcrnet_core::float`]),
//! run over the arrays held here, so host and device share one network
//! definition.
//!
//! Hand-written forward and backward passes ([`model`], [`ops`]) over
//! `matrixmultiply` (through ndarray's safe `general_mat_mul`, with
//! `matrixmultiply`'s threading) and rayon; Chamfer or pose loss
//! ([`loss`]); Adam with a step-indexed learning-rate schedule ([`adam`]);
//! seeded data pairs ([`data`]); atomic checkpoints that resume
//! bit-identically ([`checkpoint`]); a JSON-lines log; export to the f32
//! and int8 blobs ([`export`]).
//!
//! # Design
//! - **Network**: exactly [`pcrnet_core::Arch`]'s (encoder + ReLU, max-pool,
//!   head on `[template feature | source feature]`, linear 7 outputs);
//!   weights live in [`F32Params`], so the trained model runs unchanged
//!   through `pcrnet-core`'s f32 path and the quantizer.
//! - **Initialisation**: [`F32Params::init`] (He-uniform), then the output
//!   layer's weights are scaled by [`OUTPUT_INIT_SCALE`] and its `qw` bias set
//!   to 1, so an untrained network predicts nearly the identity pose
//!   (a quaternion far from zero keeps the normalisation's gradient tame).
//! - **Loss**: Chamfer between the template and the registered source
//!   (default, as the paper), or the Frobenius pose loss.
//! - **i-PCRNet**: gradients through the last pass only (see [`model`]).
//! - **Schedule**: [`Schedule`], a pure function of the global step
//!   (default: cosine to 1% of the base rate over the run).
//! - **Determinism**: every batch is a pure function of (seed, epoch,
//!   step); GEMMs never split their summed dimension between threads; all
//!   other reductions are sequential or per-element. Same seed and
//!   configuration give bit-identical weights, and a resumed run equals an
//!   uninterrupted one (both tested).

pub mod adam;
pub mod checkpoint;
pub mod cli;
pub mod data;
pub mod dataset;
pub mod degeneracy;
pub mod export;
pub mod floor;
pub mod forward;
pub mod geometry;
pub mod inspect;
pub mod lk;
pub mod lk_solver;
pub mod loss;
pub mod metrics;
pub mod model;
pub mod net;
pub mod ops;
pub mod quantize;
pub mod shapes;
pub mod template;
mod trainer;
pub mod upgrade;
pub mod view;

pub use adam::{Adam, Schedule};
pub use checkpoint::{Checkpoint, CheckpointError, Progress};
pub use data::{PairConfig, Sampling};
pub use dataset::{Dataset, Split};
pub use loss::LossKind;
pub use metrics::{Summary, rotation_error_deg, translation_error};
pub use model::{Batch, ModelKind};
pub use net::{F32Params, TrainedFor};
pub use quantize::{CalibrationRule, QuantizeError, quantize};
pub use trainer::{
    CHECKPOINT_FILE, EpochLog, LOG_FILE, OUTPUT_INIT_SCALE, RunOptions, RunSummary, StepStats,
    TrainConfig, TrainError, Trainer, evaluate, initial_params,
};

/// Encoder widths of the embedded default (`models/embedded-default-*`):
/// int8 blob 224 KB, 2.3 KB scratch. Not yet chosen by a measured
/// size/accuracy sweep.
pub const EMBEDDED_ENCODER: &[u16] = &[32, 64, 128, 256];
/// Hidden head widths of the embedded default (see above).
pub const EMBEDDED_HEAD: &[u16] = &[256, 128, 64];
