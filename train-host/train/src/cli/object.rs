//! What `pcrnet train --object FILE` checks before any epoch runs: an
//! object no model can register is refused up front (export and the device
//! would find it only after the whole training), and what reading or
//! sampling does to the object is said rather than done silently.

use std::path::Path;

use anyhow::{Context, bail};
use pcrnet_core::Degeneracy;

use crate::degeneracy::self_degeneracy;
use pcrnet_io::{DEFAULT_MAX_POINTS, Format, read_cloud_local};

/// Reads the object as training will and refuses one that fixes no pose
/// (no extent, its points on a line or in one spot); says how many points
/// were left out (a coordinate not finite) and when the object has fewer
/// points than each training cloud (`points`), which then repeats some.
pub(super) fn check_object(path: &Path, points: usize) -> anyhow::Result<()> {
    let cloud = read_cloud_local(path, DEFAULT_MAX_POINTS, Some([0.0; 3]))?;
    let shown = path.display();
    if let Some(note) = cloud.left_out_note(path) {
        eprintln!("{note}");
    }
    let verdict = self_degeneracy(&cloud.points).with_context(|| format!("{shown}"))?;
    let why = match verdict {
        None => {
            let n = cloud.points.len();
            // An OFF mesh is sampled to as many points as training asks for.
            if Format::from_path(path) != Some(Format::Off) && n < points {
                eprintln!(
                    "{shown}: {n} points, fewer than --points {points}: each training cloud repeats some of them; --points {n} uses each once"
                );
            }
            return Ok(());
        }
        Some(Degeneracy::Point) => "its points (nearly) coincide, so no rotation can be recovered",
        Some(Degeneracy::Line) => {
            "its points (nearly) lie on a line, so the rotation about it is free"
        }
    };
    bail!("{shown}: {why}; no model can register it. Give a cloud or mesh of the object's surface")
}
