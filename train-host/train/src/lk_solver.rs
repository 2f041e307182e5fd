//! PointNetLK's solver for a blob ([`pcrnet_core::format::LkSolver`]): the
//! template's side of the Lucas-Kanade step, computed at export by the
//! blob's own encoder (the int8 one for an int8 blob, so that the stored
//! `P` and a device's residuals come from the same arithmetic).
//!
//! The six moves are `pcrnet_core::lk::exp` of `d e_k` (`d` =
//! [`JACOBIAN_STEP`], as in training), applied after the encoder's own
//! centring, exactly as a device LK step moves a source; the Jacobian's
//! forward differences and damping are [`LkSolver`]'s.

use nalgebra::DVector;
use pcrnet_core::format::LkSolver as StoredSolver;
use pcrnet_core::lk::{TWIST_DIM, exp};
use pcrnet_core::{F32Model, Int8Model, Pose};

use crate::lk::{DAMPING, JACOBIAN_STEP, LkSolver};

/// The six moves of the Jacobian's forward differences.
fn moves() -> [Pose; TWIST_DIM] {
    std::array::from_fn(|k| {
        let mut xi = [0f32; TWIST_DIM];
        xi[k] = JACOBIAN_STEP as f32;
        exp(&xi)
    })
}

/// The stored rows of `P` (`6 x F` f32 little-endian) for a template
/// feature `phi` and its six moves' features.
fn rows(phi: Vec<f64>, moved: Vec<Vec<f64>>) -> Vec<u8> {
    let moved: Vec<DVector<f64>> = moved.into_iter().map(DVector::from_vec).collect();
    let solver = LkSolver::from_features(
        &DVector::from_vec(phi),
        std::array::from_fn(|k| &moved[k]),
    );
    let p = solver.pseudo_inverse();
    (0..TWIST_DIM)
        .flat_map(|k| (0..p.ncols()).map(move |j| (k, j)))
        .flat_map(|(k, j)| (p[(k, j)] as f32).to_le_bytes())
        .collect()
}

/// The blob's record of a solver with these rows.
pub fn stored(rows: &[u8]) -> StoredSolver<'_> {
    StoredSolver {
        jacobian_step: JACOBIAN_STEP as f32,
        damping: DAMPING as f32,
        rows,
    }
}

/// `P`'s rows for an int8 model's template `points` (user units), from
/// the int8 features themselves (in int8 steps).
pub fn int8_rows(model: &Int8Model<'_>, points: &[[f32; 3]]) -> pcrnet_core::Result<Vec<u8>> {
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let mut feature = |motion: &Pose| -> pcrnet_core::Result<Vec<f64>> {
        let f = model.encode_moved(points, motion, &mut scratch)?;
        Ok(f.iter().map(|&v| v as f64).collect())
    };
    let phi = feature(&Pose::IDENTITY)?;
    let moved = moves()
        .iter()
        .map(&mut feature)
        .collect::<pcrnet_core::Result<Vec<_>>>()?;
    Ok(rows(phi, moved))
}

/// `P`'s rows for an f32 model's template `points` (the model frame).
pub fn f32_rows(model: &F32Model<'_>, points: &[[f32; 3]]) -> pcrnet_core::Result<Vec<u8>> {
    let net = model.network();
    let mut scratch = vec![0f32; model.tiled_scratch_len()];
    let mut feature = |motion: &Pose| -> pcrnet_core::Result<Vec<f64>> {
        let f = net.encode_moved(points, motion, &mut scratch)?;
        Ok(f.iter().map(|&v| v as f64).collect())
    };
    let phi = feature(&Pose::IDENTITY)?;
    let moved = moves()
        .iter()
        .map(&mut feature)
        .collect::<pcrnet_core::Result<Vec<_>>>()?;
    Ok(rows(phi, moved))
}
