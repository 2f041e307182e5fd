//! Helpers the command-line tests share: the `pcrnet` binary and the
//! shipped models folder.

use std::path::PathBuf;
use std::process::Command;

/// The `pcrnet` binary this package builds, to run as a shell would.
pub fn pcrnet() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pcrnet"))
}

/// The repository's `models/` folder (shipped blobs and example clouds).
pub fn models() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models")
}
