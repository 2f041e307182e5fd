//! Checkpoints: everything needed to resume a run bit-identically.
//!
//! A checkpoint holds the configuration, the parameters, the Adam state and
//! the position in the run (epoch, step, running epoch loss). Because every
//! batch is a pure function of (seed, epoch, step) (see [`super::data`]),
//! that position *is* the random generator's state. The file is a magic
//! string then a postcard encoding; it is written to a temporary file in
//! the same folder, synced, then renamed over the old one, so a crash never
//! leaves a torn checkpoint.

use std::io::Write;
use std::path::{Path, PathBuf};

use pcrnet_core::Arch;
use serde::{Deserialize, Serialize};

use super::TrainConfig;
use super::adam::Adam;
use crate::F32Params;

/// The layout version. 3: `points` and `sampling` in the configuration;
/// 4: `resample` (and the pair options `single_view`, `identity_share`).
const MAGIC: &[u8; 8] = b"PCRNCKP4";

/// Where a run is.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Progress {
    /// Current epoch (0-based).
    pub epoch: usize,
    /// Steps done in the current epoch.
    pub step_in_epoch: usize,
    /// Steps done in the whole run.
    pub global_step: usize,
    /// Sum of the training losses of the current epoch.
    pub loss_sum: f64,
}

/// A saved training state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The run's configuration.
    pub config: TrainConfig,
    /// Network shape.
    pub arch: Arch,
    /// Parameters, as [`F32Params::layers`].
    pub layers: Vec<(Vec<f32>, Vec<f32>)>,
    /// Optimiser state.
    pub adam: Adam,
    /// Position in the run.
    pub progress: Progress,
}

/// Why a checkpoint could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// File system error.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// Not a checkpoint, or a damaged one.
    #[error("{}: not a valid checkpoint ({what})", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, synced,
/// then renamed over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

impl Checkpoint {
    /// Whether the run it saves has trained all its epochs.
    pub fn finished(&self) -> bool {
        self.progress.epoch >= self.config.epochs
    }

    /// The parameters.
    pub fn params(&self) -> F32Params {
        F32Params {
            arch: self.arch.clone(),
            layers: self.layers.clone(),
        }
    }

    /// Serialises the checkpoint.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        // Serialising owned plain data into a Vec cannot fail.
        out.extend(postcard::to_stdvec(self).unwrap_or_default());
        out
    }

    /// Writes the checkpoint atomically to `path`.
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        write_atomic(path, &self.to_bytes()).map_err(|error| CheckpointError::Io {
            path: path.to_path_buf(),
            error,
        })
    }

    /// Reads a checkpoint written by [`Checkpoint::save`].
    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let bytes = std::fs::read(path).map_err(|error| CheckpointError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        let invalid = |what: String| CheckpointError::Invalid {
            path: path.to_path_buf(),
            what,
        };
        let body = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or_else(|| invalid(
                "bad magic, or a checkpoint of an older version: its blobs were exported when its run ended; to resume or re-export it, use the pcrnet build that wrote it".into(),
            ))?;
        let ck: Checkpoint = postcard::from_bytes(body).map_err(|e| invalid(e.to_string()))?;
        let shapes: Vec<_> = ck
            .arch
            .encoder_layers()
            .chain(ck.arch.head_layers())
            .collect();
        let consistent = shapes.len() == ck.layers.len()
            && shapes.len() == ck.adam.m.len()
            && shapes.len() == ck.adam.v.len()
            && shapes
                .iter()
                .zip(&ck.layers)
                .zip(&ck.adam.m)
                .zip(&ck.adam.v)
                .all(|(((s, (w, b)), m), v)| {
                    w.len() == s.inputs * s.outputs
                        && b.len() == s.outputs
                        && m.len() == w.len() + b.len()
                        && v.len() == m.len()
                });
        if !consistent {
            return Err(invalid("sizes differ from the architecture".into()));
        }
        Ok(ck)
    }
}
