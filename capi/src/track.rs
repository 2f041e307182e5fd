//! `pcrnet_track`: one tracking step of a sensor stream (the Rust API's
//! `Int8Model::track`): the previous frame's pose refined and kept when it
//! holds, else a full registration in the same call; `pcrnet_track_view`
//! the same for a cut single view from a known viewpoint
//! (`Int8Model::track_view`).

use PcrnetStatus::*;
use pcrnet_core::{Int8Model, Options, Pose, TrackOutcome, Tracking};

use crate::types::{PcrnetRegistration, PcrnetStatus};
use crate::view::view_inputs;
use crate::{PcrnetModel, PcrnetOptions, pose_at, register_into, scratch_mut};

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
    // SAFETY: the caller's contract for every pointer.
    unsafe {
        track_into(
            model,
            points,
            n_points,
            previous,
            false,
            options,
            out,
            outcome,
            |m, source, previous, options| {
                Ok(m.track(
                    source,
                    previous,
                    options,
                    scratch_mut(scratch, scratch_len)?,
                )?)
            },
        )
    }
}

/// One tracking step of a cut single view seen from `viewpoint` `[x, y,
/// z]` (the sensor's position in the source's frame, source units: 0, 0, 0
/// for points in the camera's own frame), as `pcrnet_track` does, its
/// fallback registration guided by the view as `pcrnet_register_view`'s
/// is (starts placed by what the sensor sees, the turned ones judged by
/// the view rendered into `buffer`, `buffer_len` floats, see
/// `PCRNET_VIEW_BUFFER_LEN`). `out->reliable` is the residual's verdict,
/// as `pcrnet_track`'s; `pcrnet_check_view` checks the pose against the
/// view. Errors as `pcrnet_track` and `pcrnet_check_view` (the view is
/// rendered first: a viewpoint it refuses is an error even when the track
/// holds); nothing is written on one.
///
/// # Safety
/// As `pcrnet_track`; `viewpoint` must point to 3 readable floats and
/// `buffer` to `buffer_len` writable floats overlapping nothing else
/// (each may be null: an error).
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments, reason = "a flat C signature")]
pub unsafe extern "C" fn pcrnet_track_view(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    previous: *const f32,
    viewpoint: *const f32,
    options: *const PcrnetOptions,
    scratch: *mut i8,
    scratch_len: usize,
    buffer: *mut f32,
    buffer_len: usize,
    out: *mut PcrnetRegistration,
    outcome: *mut u32,
) -> PcrnetStatus {
    // SAFETY: the caller's contract for every pointer; `view_inputs`
    // checks the viewpoint's length and alignment.
    unsafe {
        track_into(
            model,
            points,
            n_points,
            previous,
            viewpoint.is_null(),
            options,
            out,
            outcome,
            |m, source, previous, options| {
                let (viewpoint, scratch, buffer) =
                    view_inputs(viewpoint, scratch, scratch_len, buffer, buffer_len)?;
                Ok(m.track_view(source, previous, viewpoint, options, scratch, buffer)?)
            },
        )
    }
}

/// What `pcrnet_track` and `pcrnet_track_view` share: the model, the
/// pointers that must not be null (`previous`, `outcome`, and whatever
/// `missing` says of the caller's own), the previous pose, then `step` on
/// the points (`register_into`'s checks); the result to `out` and its
/// outcome code to `outcome` on success, nothing written on an error.
///
/// # Safety
/// As `pcrnet_track`.
#[allow(clippy::too_many_arguments)]
unsafe fn track_into(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    previous: *const f32,
    missing: bool,
    options: *const PcrnetOptions,
    out: *mut PcrnetRegistration,
    outcome: *mut u32,
    step: impl FnOnce(&Int8Model<'_>, &[[f32; 3]], &Pose, &Options) -> Result<Tracking, PcrnetStatus>,
) -> PcrnetStatus {
    let m = match crate::model(model) {
        Ok(m) => m,
        Err(s) => return s,
    };
    if previous.is_null() || missing || outcome.is_null() {
        return PCRNET_ERROR_NULL_POINTER;
    }
    // SAFETY: non-null; the caller's contract (7 floats).
    let previous = match unsafe { pose_at(previous) } {
        Ok(p) => p,
        Err(s) => return s,
    };
    let mut what = PCRNET_TRACK_LOST;
    // SAFETY: the caller's contract for every pointer.
    let status = unsafe {
        register_into(points, n_points, options, out, |source, options| {
            let t = step(m, source, &previous, options)?;
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
