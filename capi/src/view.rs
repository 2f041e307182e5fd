//! A registration of a cut single view checked from the sensor's
//! viewpoint: `pcrnet_check_view`.

use PcrnetStatus::*;
use pcrnet_core::Pose;

use crate::types::PcrnetStatus;
use crate::{PcrnetModel, cloud, slice, slice_mut};

/// Floats of the image buffer `pcrnet_check_view` is best given: 32 x 32
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

/// Checks `pose` `[qw, qx, qy, qz, tx, ty, tz]` (a registration of the
/// `n_points` source points, as `PcrnetRegistration` gives it) against the
/// source seen as a cut single view from `viewpoint` `[x, y, z]` (the
/// sensor's position in the source's frame, source units; 0, 0, 0 for
/// points in the camera's own frame): the source splatted into a small
/// depth image in `buffer` (`buffer_len` floats, see
/// `PCRNET_VIEW_BUFFER_LEN`), the template's points judged on it (see
/// `pcrnet_core::scene::view`). Act on a registration only when it is
/// reliable and the check passed. Writes `out` on success; a viewpoint
/// that is not finite, among or beside the points, or a buffer under 64
/// floats, is `PCRNET_ERROR_INVALID_OPTION`; no finite point,
/// `PCRNET_ERROR_EMPTY_CLOUD`; a pose that is not finite,
/// `PCRNET_ERROR_NON_FINITE_RESULT`.
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
        let (p, v) = unsafe { (slice(pose, 7)?, slice(viewpoint, 3)?) };
        let pose = Pose {
            rotation: [p[0], p[1], p[2], p[3]],
            translation: [p[4], p[5], p[6]],
        };
        // SAFETY: the caller's contract for `points` and `buffer`.
        let (source, buffer) =
            unsafe { (cloud(points, n_points)?, slice_mut(buffer, buffer_len)?) };
        let c = m.check_view(source, [v[0], v[1], v[2]], &pose, buffer)?;
        Ok(PcrnetViewCheck {
            supported: c.supported,
            violations: c.violations,
            occluded: c.occluded,
            unobserved: c.unobserved,
            passed: c.passed,
        })
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
