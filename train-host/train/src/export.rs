//! Export of trained parameters to `pcrnet-core` blobs.

use std::path::{Path, PathBuf};

use super::checkpoint::write_atomic;
use super::data::{PairConfig, make_pair, mix_seed};
use crate::template::Reference;
use crate::{CalibrationRule, F32Params, TrainedFor, quantize};

/// File name of the exported f32 blob.
pub const F32_BLOB: &str = "model-f32.pcrn";
/// File name of the exported int8 blob.
pub const INT8_BLOB: &str = "model-int8.pcrn";

/// `count` calibration sources: the template under seeded random poses of
/// `pairs` (noise, crops and all), as the device will see it.
pub fn calibration_clouds(
    template: &[[f32; 3]],
    pairs: &PairConfig,
    count: usize,
    seed: u64,
) -> Vec<Vec<[f32; 3]>> {
    (0..count)
        .map(|i| make_pair(template, pairs, mix_seed(seed, 0xCA11, i as u64)).0)
        .collect()
}

/// Writes the f32 blob (recording `reference`: frame, template points,
/// feature) into `dir`, and the int8 blob too when `calibration` (model
/// frame) is given. Files are written atomically.
/// `trained` must say how the network was trained (the pairs' `centre`,
/// i-PCRNet's passes). Returns the paths written.
pub fn export(
    params: &F32Params,
    reference: &Reference,
    calibration: Option<&[Vec<[f32; 3]>]>,
    trained: TrainedFor,
    dir: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    if let Some(l) = params
        .layers
        .iter()
        .position(|(w, b)| w.iter().chain(b).any(|v| !v.is_finite()))
    {
        anyhow::bail!(
            "layer {l} has a NaN or infinite weight (training diverged: lower --lr or add --clip); no model written"
        );
    }
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    let f32_blob = params.to_f32_blob(reference, trained)?;
    let p = dir.join(F32_BLOB);
    write_atomic(&p, &f32_blob)?;
    written.push(p);
    if let Some(cal) = calibration {
        let int8 = quantize(params, reference, cal, CalibrationRule::default(), trained)?;
        let p = dir.join(INT8_BLOB);
        write_atomic(&p, &int8)?;
        written.push(p);
    }
    Ok(written)
}
