//! PointNetLK's solver for a blob ([`pcrnet_core::format::LkSolver`]): the
//! template's side of the Lucas-Kanade step, computed at export (and at
//! every `bind`) by the blob's own encoder: the int8 one for an int8 blob,
//! so that the stored `P` and a device's residuals come from the same
//! arithmetic.
//!
//! The moves are `pcrnet_core::lk::exp` of `+-d e_k`, applied after the
//! encoder's own centring, exactly as a device LK step moves a source; the
//! damping is [`LkSolver`]'s.
//! - f32: forward differences of step [`JACOBIAN_STEP`], as in training.
//! - int8: central differences of step [`INT8_JACOBIAN_STEP`]. An int8
//!   feature entry moves by whole steps, and a 0.01 move changes few of
//!   them, so forward differences at the training's step give a Jacobian
//!   of quantisation noise: measured on the generalisation pairs (unseen
//!   classes, 20 LK steps, LK alone), the int8 mean rotation error was
//!   25.9° with it, against 6.1° for the f32 blob; central differences
//!   gave 12.8° at 0.01, 4.4° at 0.02, 6.0° at 0.03, 5.5° at 0.05 and
//!   5.7° at 0.1 (seen classes: 8.1°, 4.2°, 4.0°, 1.8°, 1.2°; f32 2.0°).
//!   0.05 was chosen on those same pairs (RESULTS.md `generalisation`).

use nalgebra::{DMatrix, DVector};
use pcrnet_core::format::{LkSolver as StoredSolver, NearestTable, Trailer};
use pcrnet_core::lk::{TWIST_DIM, exp};
use pcrnet_core::{F32Model, Int8Model, Pose};

use crate::lk::{DAMPING, JACOBIAN_STEP, LkSolver};

/// Step of the int8 Jacobian's central differences (twist units).
pub const INT8_JACOBIAN_STEP: f64 = 0.05;

/// How a Jacobian is taken.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Differences {
    step: f64,
    central: bool,
}

const F32_DIFFERENCES: Differences = Differences {
    step: JACOBIAN_STEP,
    central: false,
};

const INT8_DIFFERENCES: Differences = Differences {
    step: INT8_JACOBIAN_STEP,
    central: true,
};

/// The move `exp(s e_k)`.
fn move_along(k: usize, s: f64) -> Pose {
    let mut xi = [0f32; TWIST_DIM];
    xi[k] = s as f32;
    exp(&xi)
}

/// The Jacobian (`F x 6`) of `feature` about the identity.
fn jacobian(
    d: Differences,
    mut feature: impl FnMut(&Pose) -> pcrnet_core::Result<Vec<f64>>,
) -> pcrnet_core::Result<DMatrix<f64>> {
    let phi = DVector::from_vec(feature(&Pose::IDENTITY)?);
    let mut j = DMatrix::zeros(phi.len(), TWIST_DIM);
    for k in 0..TWIST_DIM {
        let plus = DVector::from_vec(feature(&move_along(k, d.step))?);
        let column = if d.central {
            let minus = DVector::from_vec(feature(&move_along(k, -d.step))?);
            (plus - minus) / (2.0 * d.step)
        } else {
            (plus - &phi) / d.step
        };
        j.set_column(k, &column);
    }
    Ok(j)
}

/// The stored rows of `P` (`6 x F` f32 little-endian) for a Jacobian.
fn rows(jacobian: DMatrix<f64>) -> Vec<u8> {
    let p = LkSolver::new(jacobian).pseudo_inverse();
    (0..TWIST_DIM)
        .flat_map(|k| (0..p.ncols()).map(move |j| (k, j)))
        .flat_map(|(k, j)| (p[(k, j)] as f32).to_le_bytes())
        .collect()
}

/// A blob's trailer: the template's closest-point `table` and, given its
/// `rows`, the solver of a blob of `kind`.
pub fn trailer<'a>(
    kind: pcrnet_core::format::ModelKind,
    table: Option<NearestTable<'a>>,
    rows: Option<&'a [u8]>,
) -> Trailer<'a> {
    Trailer {
        table,
        lk: rows.map(|r| stored(kind, r)),
        ..Trailer::default()
    }
}

/// Rows of zeros for a solver of `features` entries: a placeholder that
/// lets a blob without a head load before its solver is computed.
pub fn placeholder_rows(features: usize) -> Vec<u8> {
    vec![0u8; 4 * TWIST_DIM * features]
}

/// The blob's record of a solver with these rows, for a blob of `kind`.
fn stored(kind: pcrnet_core::format::ModelKind, rows: &[u8]) -> StoredSolver<'_> {
    let d = match kind {
        pcrnet_core::format::ModelKind::Int8 => INT8_DIFFERENCES,
        pcrnet_core::format::ModelKind::F32 => F32_DIFFERENCES,
    };
    StoredSolver {
        jacobian_step: d.step as f32,
        central: d.central,
        damping: DAMPING as f32,
        rows,
    }
}

/// `P`'s rows for an int8 model's template `points` (user units), from
/// the int8 features themselves (in int8 steps).
pub fn int8_rows(model: &Int8Model<'_>, points: &[[f32; 3]]) -> pcrnet_core::Result<Vec<u8>> {
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let j = jacobian(INT8_DIFFERENCES, |motion| {
        let f = model.encode_moved(points, motion, &mut scratch)?;
        Ok(f.iter().map(|&v| v as f64).collect())
    })?;
    Ok(rows(j))
}

/// `P`'s rows for an f32 model's template `points` (the model frame).
pub fn f32_rows(model: &F32Model<'_>, points: &[[f32; 3]]) -> pcrnet_core::Result<Vec<u8>> {
    let net = model.network();
    let mut scratch = vec![0f32; model.tiled_scratch_len()];
    let j = jacobian(F32_DIFFERENCES, |motion| {
        let f = net.encode_moved(points, motion, &mut scratch)?;
        Ok(f.iter().map(|&v| v as f64).collect())
    })?;
    Ok(rows(j))
}
