//! A cut single view registered and checked from the sensor's viewpoint:
//! `pcrnet_register_view` and `pcrnet_check_view`.

use PcrnetStatus::*;
use pcrnet_core::scene::Verification;

use crate::types::{PcrnetOptions, PcrnetRegistration, PcrnetStatus};
use crate::{PcrnetModel, cloud, pose_at, register_into, scratch_mut, slice, slice_mut};

/// Floats of the image buffer `pcrnet_register_view` and
/// `pcrnet_check_view` are best given: 32 x 32
/// pixels (4 KB), enough for sources of up to about 500 points at full
/// resolution; at least 64 (8 x 8), a smaller buffer gives coarser pixels.
pub const PCRNET_VIEW_BUFFER_LEN: usize = 1024;

/// What `pcrnet_check_view` found: the stored template points, moved by the
/// pose into the view, counted by what the view says of each.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PcrnetViewCheck {
    /// On the seen surface.
    pub supported: u32,
    /// Where the sensor saw past the object (free space).
    pub violations: u32,
    /// Behind the seen surface (no evidence).
    pub occluded: u32,
    /// Behind the viewpoint (none for a sound pose).
    pub unobserved: u32,
    /// At most 10% violations among supported + violations, at least 20%
    /// support among those with an observation: the pose explains the view.
    pub passed: bool,
}

impl From<Verification> for PcrnetViewCheck {
    fn from(c: Verification) -> Self {
        PcrnetViewCheck {
            supported: c.supported,
            violations: c.violations,
            occluded: c.occluded,
            unobserved: c.unobserved,
            passed: c.passed,
        }
    }
}

/// Registers `n_points` source points, a cut single view seen from
/// `viewpoint` `[x, y, z]` (the sensor's position in the source's frame,
/// source units), as `pcrnet_register` does, with the view rendered into
/// `buffer` (`buffer_len` floats, see `PCRNET_VIEW_BUFFER_LEN`) as a test
/// the turned starts must pass besides their residual (the lowest-residual
/// one that explains the view finishes), every start first placed so that
/// the view's centroid meets the centroid of what the sensor would see of
/// the template there (`Int8Model::register_view`).
/// Writes the registration to `out` and its check against the view to
/// `out_view` on success; `out->reliable` is both verdicts (the residual's
/// and `out_view->passed`): act on the pose only when it is set. Errors as
/// `pcrnet_register` and `pcrnet_check_view`; nothing is written on one.
///
/// # Safety
/// As `pcrnet_register`; `viewpoint` must point to 3 readable floats,
/// `buffer` to `buffer_len` writable floats overlapping nothing else,
/// `out_view` to a writable `PcrnetViewCheck` (each may be null: an error).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_register_view(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    viewpoint: *const f32,
    options: *const PcrnetOptions,
    scratch: *mut i8,
    scratch_len: usize,
    buffer: *mut f32,
    buffer_len: usize,
    out: *mut PcrnetRegistration,
    out_view: *mut PcrnetViewCheck,
) -> PcrnetStatus {
    let m = match crate::model(model) {
        Ok(m) => m,
        Err(s) => return s,
    };
    if viewpoint.is_null() || out_view.is_null() {
        return PCRNET_ERROR_NULL_POINTER;
    }
    let mut seen = None;
    // SAFETY: the caller's contract for every pointer; `viewpoint` is
    // non-null, its length 3 and alignment checked by `slice`.
    let status = unsafe {
        register_into(points, n_points, options, out, |source, options| {
            let (viewpoint, scratch, buffer) =
                view_inputs(viewpoint, scratch, scratch_len, buffer, buffer_len)?;
            let r = m.register_view(source, viewpoint, options, scratch, buffer)?;
            seen = Some(r.view);
            Ok(pcrnet_core::Registration {
                reliable: r.reliable,
                ..r.registration
            })
        })
    };
    if let (PCRNET_OK, Some(v)) = (status, seen) {
        // SAFETY: checked non-null above; the caller's contract.
        unsafe { out_view.write(v.into()) };
    }
    status
}

/// A viewed call's viewpoint, scratch and view buffer ([`view_inputs`]).
pub(crate) type ViewInputs<'a> = ([f32; 3], &'a mut [i8], &'a mut [f32]);

/// The viewpoint, the scratch and the view's buffer of a call that
/// registers with a view (`pcrnet_register_view`, `pcrnet_track_view`).
///
/// # Safety
/// If non-null, `viewpoint` points to 3 readable floats, `scratch` to
/// `scratch_len` and `buffer` to `buffer_len` writable elements,
/// overlapping nothing else.
pub(crate) unsafe fn view_inputs<'a>(
    viewpoint: *const f32,
    scratch: *mut i8,
    scratch_len: usize,
    buffer: *mut f32,
    buffer_len: usize,
) -> Result<ViewInputs<'a>, PcrnetStatus> {
    // SAFETY: the caller's contract; `slice` checks null, length and alignment.
    unsafe {
        let v = slice(viewpoint, 3)?;
        Ok((
            [v[0], v[1], v[2]],
            scratch_mut(scratch, scratch_len)?,
            slice_mut(buffer, buffer_len)?,
        ))
    }
}

/// Checks `pose` `[qw, qx, qy, qz, tx, ty, tz]` (a registration of the
/// `n_points` source points, as `PcrnetRegistration` gives it) against the
/// source seen as a cut single view from `viewpoint` `[x, y, z]` (the
/// sensor's position in the source's frame, source units; 0, 0, 0 for
/// points in the camera's own frame): the source splatted into a small
/// depth image in `buffer` (`buffer_len` floats, see
/// `PCRNET_VIEW_BUFFER_LEN`), the template's points judged on it (see
/// `pcrnet_core::scene::view`). Act on a registration only when it is
/// reliable and the check passed. Writes `out` on success; a viewpoint
/// that is not finite, among or beside the points or more than 10,000
/// source radii away, or a buffer under 64 floats, is
/// `PCRNET_ERROR_INVALID_OPTION`; no finite point,
/// `PCRNET_ERROR_EMPTY_CLOUD`; a pose that is not finite or whose
/// quaternion is not of unit length, `PCRNET_ERROR_INVALID_POSE`.
///
/// # Safety
/// `model` as `pcrnet_register`; `points` must point to `3 * n_points`
/// readable floats, `viewpoint` to 3 and `pose` to 7, `buffer` to
/// `buffer_len` writable floats, `out` to a writable `PcrnetViewCheck`
/// (each may be null: an error).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_check_view(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    viewpoint: *const f32,
    pose: *const f32,
    buffer: *mut f32,
    buffer_len: usize,
    out: *mut PcrnetViewCheck,
) -> PcrnetStatus {
    let run = || -> Result<PcrnetViewCheck, PcrnetStatus> {
        let m = crate::model(model)?;
        if pose.is_null() || viewpoint.is_null() || out.is_null() {
            return Err(PCRNET_ERROR_NULL_POINTER);
        }
        // SAFETY: non-null; the caller's contract (7 and 3 floats); alignment checked.
        let (pose, v) = unsafe { (pose_at(pose)?, slice(viewpoint, 3)?) };
        // SAFETY: the caller's contract for `points` and `buffer`.
        let (source, buffer) =
            unsafe { (cloud(points, n_points)?, slice_mut(buffer, buffer_len)?) };
        Ok(m.check_view(source, [v[0], v[1], v[2]], &pose, buffer)?
            .into())
    };
    match run() {
        Ok(c) => {
            // SAFETY: checked non-null in `run`; the caller's contract.
            unsafe { out.write(c) };
            PCRNET_OK
        }
        Err(s) => s,
    }
}
