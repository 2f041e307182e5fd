//! `pcrnet_track`: one tracking step of a sensor stream (the Rust API's
//! `Int8Model::track`): the previous frame's pose refined and kept when it
//! holds, else a full registration in the same call.

use PcrnetStatus::*;
use pcrnet_core::{Pose, TrackOutcome};

use crate::types::{PcrnetRegistration, PcrnetStatus};
use crate::{PcrnetModel, PcrnetOptions, register_into, scratch_mut, slice};

/// `pcrnet_track`'s outcome: refined from the previous pose, reliable: the
/// track is kept (the network did not run).
pub const PCRNET_TRACK_KEPT: u32 = 0;
/// `pcrnet_track`'s outcome: the previous pose did not hold; the full
/// registration in the same call found a reliable pose.
pub const PCRNET_TRACK_RECOVERED: u32 = 1;
/// `pcrnet_track`'s outcome: no reliable pose either way (the result is
/// the registration's, `reliable` false): track the next frame from the
/// last reliable pose (its step falls back to a registration again).
pub const PCRNET_TRACK_LOST: u32 = 2;

/// One tracking step: refines `previous`, the last frame's pose
/// `[qw, qx, qy, qz, tx, ty, tz]` (source units, as `PcrnetRegistration`
/// gives it), by ICP on the points, and keeps it when reliable and within
/// one step; else registers the points afresh, as `pcrnet_register` does.
/// Writes the result to `out` and `PCRNET_TRACK_KEPT`, `_RECOVERED` or
/// `_LOST` to `outcome` on success. A `previous` that is not finite or
/// whose quaternion is not of unit length is `PCRNET_ERROR_INVALID_POSE`.
///
/// # Safety
/// As `pcrnet_register`; `previous` must point to 7 readable floats and
/// `outcome` to a writable `uint32_t` (or be null).
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments, reason = "a flat C signature")]
pub unsafe extern "C" fn pcrnet_track(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    previous: *const f32,
    options: *const PcrnetOptions,
    scratch: *mut i8,
    scratch_len: usize,
    out: *mut PcrnetRegistration,
    outcome: *mut u32,
) -> PcrnetStatus {
    let m = match crate::model(model) {
        Ok(m) => m,
        Err(s) => return s,
    };
    if previous.is_null() || outcome.is_null() {
        return PCRNET_ERROR_NULL_POINTER;
    }
    // SAFETY: non-null; the caller's contract (7 floats); alignment checked.
    let previous = match unsafe { slice(previous, 7) } {
        Ok(p) => Pose {
            rotation: [p[0], p[1], p[2], p[3]],
            translation: [p[4], p[5], p[6]],
        },
        Err(s) => return s,
    };
    let mut what = PCRNET_TRACK_LOST;
    // SAFETY: the caller's contract for every pointer.
    let status = unsafe {
        register_into(points, n_points, options, out, |source, options| {
            let scratch = scratch_mut(scratch, scratch_len)?;
            let t = m.track(source, &previous, options, scratch)?;
            what = match t.outcome {
                TrackOutcome::Kept => PCRNET_TRACK_KEPT,
                TrackOutcome::Recovered => PCRNET_TRACK_RECOVERED,
                TrackOutcome::Lost => PCRNET_TRACK_LOST,
            };
            Ok(t.registration)
        })
    };
    if status == PCRNET_OK {
        // SAFETY: checked non-null above; the caller's contract.
        unsafe { outcome.write(what) };
    }
    status
}
