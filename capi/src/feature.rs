//! The feature-space check of a pose: `pcrnet_feature_distance`.

use PcrnetStatus::*;

use crate::types::PcrnetStatus;
use crate::{PcrnetModel, cloud, pose_at, scratch_mut};

/// How far the points moved by `pose` `[qw, qx, qy, qz, tx, ty, tz]`
/// (source units, as `PcrnetRegistration` gives it) lie from the template
/// in the network's feature space: the relative distance between the
/// encoder's feature of the moved points and the template's (0: the same
/// feature; see `Int8Model::feature_distance`). One encoder pass over at most
/// 128 points (256 for a PointNetLK blob; every k-th: the sample the blob's
/// registrations encode, as the template's feature was pooled). Writes it to `out` on success; a pose that is not finite is
/// `PCRNET_ERROR_NON_FINITE_RESULT`.
///
/// # Safety
/// `model` as `pcrnet_register`; `points` must point to `3 * n_points`
/// readable floats, `pose` to 7, `scratch` to `scratch_len` writable
/// bytes, `out` to a writable float (each may be null: an error).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_feature_distance(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    pose: *const f32,
    scratch: *mut i8,
    scratch_len: usize,
    out: *mut f32,
) -> PcrnetStatus {
    let run = || -> Result<f32, PcrnetStatus> {
        let m = crate::model(model)?;
        if pose.is_null() || out.is_null() {
            return Err(PCRNET_ERROR_NULL_POINTER);
        }
        // SAFETY: non-null; the caller's contract (7 floats).
        let pose = unsafe { pose_at(pose)? };
        // SAFETY: the caller's contract for `points` and `scratch`.
        let (source, scratch) =
            unsafe { (cloud(points, n_points)?, scratch_mut(scratch, scratch_len)?) };
        Ok(m.feature_distance(source, &pose, scratch)?)
    };
    match run() {
        Ok(d) => {
            // SAFETY: checked non-null in `run`; the caller's contract.
            unsafe { out.write(d) };
            PCRNET_OK
        }
        Err(s) => s,
    }
}
