//! `pcrnet_locate`: the object found in a raw depth frame and registered
//! (the Rust API's `Int8Model::locate`): the dominant plane taken out,
//! clusters kept by their size, the largest few registered and checked
//! against the frame, the best verified one reported; and `pcrnet_follow`:
//! the next frame of a stream from the last result (`Int8Model::follow`).

use PcrnetStatus::*;
use pcrnet_core::Int8Model;
use pcrnet_core::locate::{Located, MAX_CANDIDATES};
use pcrnet_core::scene::{self, DepthImage, Intrinsics, PlaneChoice, SceneOptions};

use crate::types::{PcrnetRegistration, PcrnetStatus};
use crate::{PcrnetModel, PcrnetOptions, scratch_mut, slice, slice_mut};

/// A 16-bit depth image the caller owns: `height` rows of `stride`
/// pixels (`width` of them used), row-major, from the top-left pixel.
/// The sensor frame is x right, y down, z forward (the usual pinhole
/// camera), in `depth_scale` user units per count.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcrnetDepthImage {
    /// `height * stride` depth values, 2-byte aligned.
    pub depth: *const u16,
    /// Pixels a row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Pixels from one row's start to the next's (at least `width`).
    pub stride: usize,
    /// Focal length along a row, pixels.
    pub fx: f32,
    /// Focal length along a column, pixels.
    pub fy: f32,
    /// Principal point, column.
    pub cx: f32,
    /// Principal point, row.
    pub cy: f32,
    /// User units per depth count (0.001 turns millimetres into metres);
    /// the template's units, as for `pcrnet_register`'s points.
    pub depth_scale: f32,
    /// The value of a pixel the sensor has no depth for (usually 0).
    pub invalid: u16,
}

/// How to look for the object (`pcrnet_scene_options_default` fills the
/// defaults); the rest of the scene settings follow from the model's
/// object radius (`pcrnet_core::scene::SceneOptions::for_object`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcrnetSceneOptions {
    /// Pixels between grid samples (4).
    pub step: u32,
    /// Candidates registered, largest clusters first (3; at most 8).
    pub candidates: u32,
    /// With `has_up`: the template's up axis (template frame: the axis
    /// pointing away from the surface it rests on). Each candidate is then
    /// registered by a yaw sweep about the plane's normal, for a view from
    /// one side in any yaw.
    pub up: [f32; 3],
    /// Yaw starts of that sweep (12: 30 degrees apart).
    pub yaws: u32,
    /// With `has_plane`: the plane the objects stand on, unit normal
    /// towards the sensor (sensor frame) ...
    pub plane_normal: [f32; 3],
    /// ... and the sensor's distance from it, user units. Without
    /// `has_plane` the dominant plane is found (seeded RANSAC).
    pub plane_offset: f32,
    /// `up` is given.
    pub has_up: bool,
    /// `plane_normal` and `plane_offset` are given.
    pub has_plane: bool,
    /// Check each candidate's pose against the frame (true): a pose is
    /// reliable only if the template's points that should be visible are
    /// seen where it puts them, and none lies in front of what the sensor saw.
    pub verify: bool,
}

/// What `pcrnet_locate` found.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcrnetLocated {
    /// With `found`: the winner's registration, its pose mapping the
    /// sensor frame onto the template (user units), its `reliable` the
    /// registration's own verdict (see `reliable` below for the frame's).
    pub registration: PcrnetRegistration,
    /// With `has_plane`: the plane taken out (unit normal towards the
    /// sensor) ...
    pub plane_normal: [f32; 3],
    /// ... and the sensor's distance from it, user units.
    pub plane_offset: f32,
    /// With `verified`: the winner's template points seen at their place ...
    pub supported: u32,
    /// ... in front of what the sensor saw (free space) or beneath the
    /// plane ...
    pub violations: u32,
    /// ... behind it ...
    pub occluded: u32,
    /// ... and at a pixel without depth (for those outside the frame see
    /// `outside`, the last field).
    pub unobserved: u32,
    /// The winner's place among the kept clusters (largest first).
    pub cluster: u32,
    /// Clusters kept by their size.
    pub clusters_kept: u32,
    /// Candidates registered.
    pub candidates_tried: u32,
    /// A candidate was registered (a kept cluster exists).
    pub found: bool,
    /// The winner's verdict: checked against the frame when `verified`,
    /// else its registration's.
    pub reliable: bool,
    /// The winner was checked against the frame.
    pub verified: bool,
    /// A plane was found or given.
    pub has_plane: bool,
    /// With `verified`: the winner's template points outside the frame or
    /// behind the sensor (a winner with more than 5% of its points there
    /// is not reliable: out of view). Last, so that the fields before it
    /// keep the places they had before it was added.
    pub outside: u32,
}

impl Default for PcrnetSceneOptions {
    /// What `pcrnet_scene_options_default` writes: a 4-pixel grid, 3
    /// candidates, the plane found, no up axis (z when set), 12 yaws,
    /// poses verified.
    fn default() -> Self {
        PcrnetSceneOptions {
            step: 4,
            candidates: 3,
            up: [0.0, 0.0, 1.0],
            yaws: scene::DEFAULT_YAWS as u32,
            plane_normal: [0.0; 3],
            plane_offset: 0.0,
            has_up: false,
            has_plane: false,
            verify: true,
        }
    }
}

impl PcrnetSceneOptions {
    /// The Rust scene options these give for an object of `radius` user
    /// units: [`SceneOptions::for_object`] with this step, plane, check, up
    /// axis and yaws.
    pub fn scene_options(&self, radius: f32) -> SceneOptions {
        let defaults = SceneOptions::for_object(radius);
        SceneOptions {
            step: self.step as usize,
            plane: if self.has_plane {
                PlaneChoice::Given(scene::Plane {
                    normal: self.plane_normal,
                    offset: self.plane_offset,
                })
            } else {
                defaults.plane
            },
            verify: if self.verify { defaults.verify } else { None },
            up: self.has_up.then_some(self.up),
            yaws: self.yaws as usize,
            ..defaults
        }
    }
}

impl From<&Located> for PcrnetLocated {
    fn from(located: &Located) -> Self {
        let count = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        let best = located.best;
        let check = best.and_then(|b| b.verification);
        let plane = located.segmentation.plane;
        PcrnetLocated {
            registration: match &best {
                Some(b) => (&b.registration).into(),
                None => PcrnetRegistration::default(),
            },
            plane_normal: plane.map_or([0.0; 3], |p| p.normal),
            plane_offset: plane.map_or(0.0, |p| p.offset),
            supported: check.map_or(0, |v| v.supported),
            violations: check.map_or(0, |v| v.violations),
            occluded: check.map_or(0, |v| v.occluded),
            unobserved: check.map_or(0, |v| v.unobserved),
            outside: check.map_or(0, |v| v.outside),
            cluster: best.map_or(0, |b| count(b.cluster)),
            clusters_kept: count(located.segmentation.clusters.kept.len()),
            candidates_tried: count(located.tried.len()),
            found: best.is_some(),
            reliable: best.is_some_and(|b| b.reliable),
            verified: check.is_some(),
            has_plane: plane.is_some(),
        }
    }
}

/// The label elements (`uint16_t`) `pcrnet_locate` needs for a
/// `width x height` frame sampled every `step` pixels (0 for a step of 0).
#[unsafe(no_mangle)]
pub extern "C" fn pcrnet_scene_labels_len(width: usize, height: usize, step: u32) -> usize {
    scene::labels_len(width, height, step as usize)
}

/// Writes the default scene options to `out` (nothing for null): a 4-pixel
/// grid, 3 candidates, the plane found, no up axis, poses verified.
///
/// # Safety
/// `out` must be null or point to a writable `PcrnetSceneOptions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_scene_options_default(out: *mut PcrnetSceneOptions) {
    if out.is_null() {
        return;
    }
    // SAFETY: non-null; the caller's contract.
    unsafe { out.write(PcrnetSceneOptions::default()) };
}

/// Writes the default scene options for `model`'s object to `out`: those
/// of `pcrnet_scene_options_default`, with the up axis the blob was
/// exported with (`pcrnet train --up`, format 7) in `up` and `has_up` set
/// when it has one, so that `pcrnet_locate` sweeps the yaw about the plane
/// it finds. `PCRNET_ERROR_NULL_POINTER` or `PCRNET_ERROR_NOT_LOADED`,
/// writing nothing, otherwise.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`; `out` null or point
/// to a writable `PcrnetSceneOptions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_scene_options_for_model(
    model: *const PcrnetModel,
    out: *mut PcrnetSceneOptions,
) -> PcrnetStatus {
    if out.is_null() {
        return PcrnetStatus::PCRNET_ERROR_NULL_POINTER;
    }
    match crate::model(model) {
        Ok(m) => {
            let defaults = PcrnetSceneOptions::default();
            let options = match m.up_axis() {
                Some(up) => PcrnetSceneOptions {
                    up,
                    has_up: true,
                    ..defaults
                },
                None => defaults,
            };
            // SAFETY: non-null; the caller's contract.
            unsafe { out.write(options) };
            PcrnetStatus::PCRNET_OK
        }
        Err(status) => status,
    }
}

/// Finds the model's object in a depth frame and registers it: the
/// dominant plane (found, or given in `scene`) taken out, what stands off
/// it split into clusters, those the size of the object kept, the largest
/// `scene->candidates` registered as `pcrnet_register` does (each from at
/// most `points_capacity` of its points) and checked against the frame,
/// the best reliable one reported. A frame without a kept cluster is
/// success with `found` false. Writes `out` on success.
///
/// Buffers, all caller-owned and not overlapping: `labels`, at least
/// `pcrnet_scene_labels_len(width, height, step)` elements; `points`,
/// `3 * points_capacity` floats (512 points is plenty); `scratch` as for
/// `pcrnet_register`. A bad frame or scene setting is
/// `PCRNET_ERROR_INVALID_FRAME`.
///
/// # Safety
/// `model`, `options`, `scratch` as `pcrnet_register` says; `image` must
/// point to a `PcrnetDepthImage` whose `depth` holds `height * stride`
/// readable values; `scene` to a `PcrnetSceneOptions`; `labels` to
/// `labels_len` writable `uint16_t`; `points` to `3 * points_capacity`
/// writable floats; `out` to a writable `PcrnetLocated` (each may be null,
/// which is a status).
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments, reason = "a flat C signature")]
pub unsafe extern "C" fn pcrnet_locate(
    model: *const PcrnetModel,
    image: *const PcrnetDepthImage,
    scene: *const PcrnetSceneOptions,
    options: *const PcrnetOptions,
    labels: *mut u16,
    labels_len: usize,
    points: *mut f32,
    points_capacity: usize,
    scratch: *mut i8,
    scratch_len: usize,
    out: *mut PcrnetLocated,
) -> PcrnetStatus {
    let buffers = Buffers {
        labels,
        labels_len,
        points,
        points_capacity,
        scratch,
        scratch_len,
    };
    // SAFETY: the caller's contract, passed on.
    unsafe {
        on_frame(
            model,
            image,
            scene,
            options,
            buffers,
            out,
            |m, frame, scene, options, b| {
                let candidates = (scene.candidates as usize).min(MAX_CANDIDATES);
                let scene_options = scene.scene_options(m.object_radius());
                let (labels, points, scratch) = b;
                Ok(m.locate(
                    frame,
                    &scene_options,
                    candidates,
                    options,
                    labels,
                    points,
                    scratch,
                )?)
            },
        )
    }
}

/// Follows the model's object into the next frame of a stream
/// (`Int8Model::follow`): `previous` is the pose of the last frame (7
/// floats, `qw qx qy qz tx ty tz`, as `pcrnet_locate` or this call wrote it
/// in `out->registration`), and `scene` should carry the plane the last
/// result found (`has_plane`, `plane_normal`, `plane_offset` copied from
/// it: no plane search then). The cluster nearest where `previous` put the
/// object, in a box of 1.5 object radii about it, is registered by ICP
/// from `previous` and checked against the frame; `out` as
/// `pcrnet_locate` writes it (`candidates_tried` 1 at most; no turn
/// reported: keep the last `pcrnet_locate`'s). Act on it only when the
/// status is `PCRNET_OK` and `reliable`; otherwise call `pcrnet_locate`
/// again (the object moved too far, left the box or is hidden). Without
/// `has_plane` the plane is searched for in the box. A `previous`
/// that is not finite or not a unit rotation is
/// `PCRNET_ERROR_INVALID_POSE`; buffers and other statuses as
/// `pcrnet_locate`.
///
/// # Safety
/// As `pcrnet_locate`; `previous` must point to 7 readable floats (or be
/// null, which is a status).
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments, reason = "a flat C signature")]
pub unsafe extern "C" fn pcrnet_follow(
    model: *const PcrnetModel,
    image: *const PcrnetDepthImage,
    scene: *const PcrnetSceneOptions,
    previous: *const f32,
    options: *const PcrnetOptions,
    labels: *mut u16,
    labels_len: usize,
    points: *mut f32,
    points_capacity: usize,
    scratch: *mut i8,
    scratch_len: usize,
    out: *mut PcrnetLocated,
) -> PcrnetStatus {
    // The model first, as the other calls check it.
    if let Err(s) = crate::model(model) {
        return s;
    }
    // SAFETY: the caller's contract: 7 floats or null.
    let previous = match unsafe { crate::pose_at(previous) } {
        Ok(p) => p,
        Err(s) => return s,
    };
    let buffers = Buffers {
        labels,
        labels_len,
        points,
        points_capacity,
        scratch,
        scratch_len,
    };
    // SAFETY: the caller's contract, passed on.
    unsafe {
        on_frame(
            model,
            image,
            scene,
            options,
            buffers,
            out,
            |m, frame, scene, options, b| {
                let scene_options = scene.scene_options(m.object_radius());
                let (labels, points, scratch) = b;
                Ok(m.follow(
                    frame,
                    &scene_options,
                    &previous,
                    None,
                    options,
                    labels,
                    points,
                    scratch,
                )?)
            },
        )
    }
}

/// The caller's buffers of one scene call, as passed.
struct Buffers {
    labels: *mut u16,
    labels_len: usize,
    points: *mut f32,
    points_capacity: usize,
    scratch: *mut i8,
    scratch_len: usize,
}

/// The buffers as slices: labels, points, scratch.
type Slices<'b> = (&'b mut [u16], &'b mut [[f32; 3]], &'b mut [i8]);

/// What `pcrnet_locate` and `pcrnet_follow` share: the model, the frame
/// and the options checked and read, the buffers as slices, `call` run on
/// them, its result written to `out`.
///
/// # Safety
/// As `pcrnet_locate`.
unsafe fn on_frame(
    model: *const PcrnetModel,
    image: *const PcrnetDepthImage,
    scene: *const PcrnetSceneOptions,
    options: *const PcrnetOptions,
    buffers: Buffers,
    out: *mut PcrnetLocated,
    call: impl FnOnce(
        &Int8Model<'static>,
        &DepthImage<'_>,
        &PcrnetSceneOptions,
        &pcrnet_core::Options,
        Slices<'_>,
    ) -> Result<Located, PcrnetStatus>,
) -> PcrnetStatus {
    let run = || -> Result<PcrnetLocated, PcrnetStatus> {
        let m = crate::model(model)?;
        if image.is_null() || scene.is_null() || options.is_null() || out.is_null() {
            return Err(PCRNET_ERROR_NULL_POINTER);
        }
        // SAFETY: non-null; the caller's contract.
        let (image, scene, options) = unsafe { (&*image, &*scene, &*options) };
        let options = pcrnet_core::Options::try_from(options)?;
        let pixels = image
            .height
            .checked_mul(image.stride)
            .ok_or(PCRNET_ERROR_INVALID_FRAME)?;
        // SAFETY: the caller's contract: `height * stride` values.
        let depth = unsafe { slice(image.depth, pixels)? };
        let intrinsics = Intrinsics {
            fx: image.fx,
            fy: image.fy,
            cx: image.cx,
            cy: image.cy,
        };
        let frame = DepthImage::new(
            depth,
            image.width,
            image.height,
            image.stride,
            intrinsics,
            image.depth_scale,
            image.invalid,
        )?;
        let b = &buffers;
        // SAFETY: the caller's contract for `labels`, `points` and `scratch`.
        let slices = unsafe {
            (
                slice_mut(b.labels, b.labels_len)?,
                slice_mut(b.points as *mut [f32; 3], b.points_capacity)?,
                scratch_mut(b.scratch, b.scratch_len)?,
            )
        };
        let located = call(m, &frame, scene, &options, slices)?;
        Ok(PcrnetLocated::from(&located))
    };
    match run() {
        Ok(r) => {
            // SAFETY: checked non-null in `run`; the caller's contract.
            unsafe { out.write(r) };
            PCRNET_OK
        }
        Err(s) => s,
    }
}
