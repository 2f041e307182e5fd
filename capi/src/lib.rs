//! C API of `pcrnet-core`: load a model blob, register a point cloud, read
//! the result and its confidence, with every byte of memory owned by the
//! caller. The header is `capi/include/pcrnet.h`, generated from this crate
//! by `cargo xtask c-header` (CI fails when it is stale).
//!
//! ```c
//! static PcrnetModel model;                  // handle storage, caller-owned
//! static int8_t scratch[64 * 1024];          // >= pcrnet_model_scratch_len(&model, 1)
//! if (pcrnet_model_load(blob, blob_len, &model) != PCRNET_OK) { ... }
//! PcrnetOptions options;
//! pcrnet_options_default(&options);
//! PcrnetRegistration r;
//! int32_t status = pcrnet_register(&model, points, n_points, &options,
//!                                  scratch, sizeof scratch, &r);
//! if (status != PCRNET_OK) puts(pcrnet_status_message(status));
//! else if (r.reliable) act_on(r.rotation, r.translation);
//! ```
//!
//! # Ownership, lifetimes, alignment
//! - The **blob** stays where it is (flash, usually) and must outlive the
//!   model handle: the handle points into it. Any alignment.
//! - The **model handle** (`PcrnetModel`) is plain storage the caller
//!   declares (static, stack); `pcrnet_model_load` fills it. It is
//!   read-only afterwards and may be shared between calls.
//! - **Points** are `n_points x 3` floats (`x0 y0 z0 x1 ...`) in the
//!   template's units, 4-byte aligned (any `float` array is).
//! - **Scratch** is the working memory of one call, any alignment; it must
//!   not overlap the blob, the points or the outputs. A bigger scratch
//!   (up to `pcrnet_model_scratch_len` with tile `PCRNET_MAX_TILE`)
//!   runs faster; the results are identical for every size. On an x86-64
//!   host (AVX2) or an aarch64 one (the dot-product extension),
//!   `pcrnet_model_host_scratch_len` bytes also let the encoder run its
//!   block kernel (several times faster, same results).
//!
//! # Errors
//! Every function that can fail returns a status (`PcrnetStatus`);
//! outputs are written only on [`PCRNET_OK`].
//! `pcrnet_status_message` gives each status's explanation. A null or
//! misaligned pointer is a status, not a crash. No function allocates or
//! panics.
//!
//! Results are bit-identical to `pcrnet-core`'s Rust API on every target:
//! this layer only converts types.
#![cfg_attr(target_os = "none", no_std)]
// The boundary takes raw pointers from C; every dereference below is
// preceded by the checks its safety comment names.
#![allow(unsafe_code)]

use core::ffi::c_char;
use core::mem::{align_of, size_of};

mod feature;
mod locate;
mod prepared;
mod track;
mod types;
mod view;
pub use feature::pcrnet_feature_distance;
pub use locate::{
    PcrnetDepthImage, PcrnetLocated, PcrnetSceneOptions, pcrnet_follow, pcrnet_locate,
    pcrnet_scene_labels_len, pcrnet_scene_options_default, pcrnet_scene_options_for_model,
};
pub use prepared::{
    PCRNET_PREPARED_SIZE, PCRNET_PREPARED_WORDS, PcrnetPrepared, pcrnet_prepare,
    pcrnet_prepared_network_pose, pcrnet_prepared_register,
};
pub use track::{
    PCRNET_TRACK_KEPT, PCRNET_TRACK_LOST, PCRNET_TRACK_RECOVERED, pcrnet_track, pcrnet_track_view,
};
pub use types::{
    PCRNET_DEGENERATE_LINE, PCRNET_DEGENERATE_NONE, PCRNET_DEGENERATE_POINT,
    PCRNET_METRIC_POINT_TO_PLANE, PCRNET_METRIC_POINT_TO_POINT, PcrnetOptions, PcrnetRegistration,
    PcrnetStatus,
};
pub use view::{PCRNET_VIEW_BUFFER_LEN, PcrnetViewCheck, pcrnet_check_view, pcrnet_register_view};

use PcrnetStatus::*;
use pcrnet_core::{Int8Model, MAX_TILE, Options, Pose, Registration};

/// Most points per encoder pass (`pcrnet_core::MAX_TILE`); a scratch
/// sized for it is the fastest.
pub const PCRNET_MAX_TILE: usize = 8;

const _: () = assert!(PCRNET_MAX_TILE == MAX_TILE);

/// Storage words of a `PcrnetModel` (8 bytes each; 2,560 bytes, the
/// same on every target: the Rust model takes 1,944 on 64-bit hosts and
/// less on 32-bit cores, checked at compile time).
pub const PCRNET_MODEL_WORDS: usize = 320;

/// A loaded model: storage the caller owns, filled by `pcrnet_model_load`.
/// Its contents are private; its size and 8-byte alignment are fixed on
/// every target.
#[repr(C)]
pub struct PcrnetModel {
    storage: [u64; PCRNET_MODEL_WORDS],
}

impl PcrnetModel {
    /// A handle that is not loaded yet (all zeros, as a C `static` is).
    pub const fn new() -> Self {
        PcrnetModel {
            storage: [0; PCRNET_MODEL_WORDS],
        }
    }
}

impl Default for PcrnetModel {
    fn default() -> Self {
        Self::new()
    }
}

/// Bytes of a `PcrnetModel` (`8 * PCRNET_MODEL_WORDS`), for C code to
/// check its view of the type:
/// `_Static_assert(sizeof(PcrnetModel) == PCRNET_MODEL_SIZE, "...")`.
pub const PCRNET_MODEL_SIZE: usize = 2560;

const _: () = assert!(size_of::<PcrnetModel>() == PCRNET_MODEL_SIZE);
const _: () = assert!(PCRNET_MODEL_SIZE == 8 * PCRNET_MODEL_WORDS);

// The handle must hold the Rust model on every target.
const _: () = assert!(size_of::<Int8Model<'static>>() <= size_of::<PcrnetModel>());
const _: () = assert!(align_of::<Int8Model<'static>>() <= align_of::<PcrnetModel>());

/// Marks a handle filled by `pcrnet_model_load` (first storage word).
const LOADED: u64 = 0x5043_524e_4c4f_4144; // "PCRNLOAD"

/// Byte offset of the Rust model inside the handle's storage: after the marker.
const MODEL_AT: usize = 8;

const _: () = assert!(MODEL_AT + size_of::<Int8Model<'static>>() <= size_of::<PcrnetModel>());

/// The model a loaded handle holds, or a status.
fn model(handle: *const PcrnetModel) -> Result<&'static Int8Model<'static>, PcrnetStatus> {
    if handle.is_null() {
        return Err(PCRNET_ERROR_NULL_POINTER);
    }
    // SAFETY: non-null, and a PcrnetModel is always readable as its u64
    // words (the C type has the same size and alignment).
    let marker = unsafe { (*handle).storage[0] };
    if marker != LOADED {
        return Err(PCRNET_ERROR_NOT_LOADED);
    }
    // SAFETY: the marker is written only by pcrnet_model_load right after
    // it stored a valid Int8Model at MODEL_AT (in bounds and aligned: 8
    // bytes in, checked by the const asserts above). The blob it borrows
    // outlives the handle by the API's contract ("'static" stands for that).
    Ok(unsafe { &*((handle as *const u8).add(MODEL_AT) as *const Int8Model<'static>) })
}

/// `len` elements at `ptr` as a slice; null with `len > 0` is an error,
/// and so is a pointer not aligned for `T`.
///
/// # Safety
/// If non-null, `ptr` must point to `len` readable `T` that stay valid and
/// unaliased by writes for the returned lifetime.
unsafe fn slice<'a, T>(ptr: *const T, len: usize) -> Result<&'a [T], PcrnetStatus> {
    if len == 0 {
        return Ok(&[]);
    }
    addressable::<T>(len)?;
    if ptr.is_null() {
        return Err(PCRNET_ERROR_NULL_POINTER);
    }
    if !(ptr as usize).is_multiple_of(align_of::<T>()) {
        return Err(PCRNET_ERROR_MISALIGNED);
    }
    // SAFETY: non-null, aligned, and the caller's contract above.
    Ok(unsafe { core::slice::from_raw_parts(ptr, len) })
}

/// The pose `[qw, qx, qy, qz, tx, ty, tz]` at `pose` (as
/// `PcrnetRegistration` gives it); null or misaligned is an error.
///
/// # Safety
/// If non-null, `pose` must point to 7 readable floats.
unsafe fn pose_at(pose: *const f32) -> Result<pcrnet_core::Pose, PcrnetStatus> {
    // SAFETY: the caller's contract.
    let p = unsafe { slice(pose, 7) }?;
    Ok(pcrnet_core::Pose {
        rotation: [p[0], p[1], p[2], p[3]],
        translation: [p[4], p[5], p[6]],
    })
}

/// Validates `blob` (magic, version, CRC, sizes, every parameter) and fills
/// `model`. The blob must stay valid and unchanged while `model` is used.
/// On failure `model` is marked not loaded.
///
/// # Safety
/// `blob` must point to `blob_len` readable bytes (or be null), and
/// `model` to writable storage of a `PcrnetModel` (or be null).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_model_load(
    blob: *const u8,
    blob_len: usize,
    model: *mut PcrnetModel,
) -> PcrnetStatus {
    if model.is_null() {
        return PCRNET_ERROR_NULL_POINTER;
    }
    // SAFETY: non-null and the caller's contract: the storage is writable.
    unsafe { (*model).storage[0] = 0 };
    // SAFETY: the caller's contract for `blob`; it outlives the handle.
    let bytes: &'static [u8] = match unsafe { slice(blob, blob_len) } {
        Ok(b) => b,
        Err(s) => return s,
    };
    match Int8Model::from_bytes(bytes) {
        Ok(m) => {
            // SAFETY: in bounds and aligned (const asserts above); the
            // storage is plain words, so overwriting needs no drop.
            unsafe {
                core::ptr::write(
                    (model as *mut u8).add(MODEL_AT) as *mut Int8Model<'static>,
                    m,
                );
                (*model).storage[0] = LOADED;
            }
            PCRNET_OK
        }
        Err(e) => e.into(),
    }
}

/// Bytes of scratch a call needs with `tile` points per encoder pass
/// (1..=`PCRNET_MAX_TILE`; the largest is the fastest); 0 for a handle
/// that is not loaded or a tile out of range.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_model_scratch_len(model: *const PcrnetModel, tile: usize) -> usize {
    match self::model(model) {
        Ok(m) if (1..=MAX_TILE).contains(&tile) => m.scratch_len(tile),
        _ => 0,
    }
}

/// Bytes of scratch with which a host build of this library on an x86-64
/// CPU with AVX2, or an aarch64 one with the dot-product extension,
/// encodes many points per weight pass (the block kernel, picked at run
/// time; results identical bit for bit): the `PCRNET_MAX_TILE` scratch
/// plus the kernel's int16 weights and activations (and the room the Rust
/// API's `Int8Model::prepare` folds the head's template half into, which
/// these calls leave unused). Firmware builds never use the extra bytes:
/// give them `pcrnet_model_scratch_len`. 0 for a handle that is not
/// loaded.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_model_host_scratch_len(model: *const PcrnetModel) -> usize {
    match self::model(model) {
        Ok(m) => m.host_scratch_len(),
        _ => 0,
    }
}

/// Network passes the model was trained for (1: PCRNet; more: i-PCRNet),
/// the `passes` to register with; 0 for a handle that is not loaded.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_model_trained_passes(model: *const PcrnetModel) -> u32 {
    self::model(model).map_or(0, |m| u32::try_from(m.trained_passes()).unwrap_or(u32::MAX))
}

/// The template's residual floor, a share of its size, when the blob
/// carries one (format 6, measured by the exporter on the template's
/// points beyond those stored); -1 when it does not or for a handle that
/// is not loaded. `pcrnet_options_for_model` calibrates `max_residual`
/// with it.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_model_residual_floor(model: *const PcrnetModel) -> f32 {
    self::model(model)
        .ok()
        .and_then(|m| m.residual_floor())
        .unwrap_or(-1.0)
}

/// Writes the recommended options (`pcrnet_core::Options::default()`:
/// one pass, 10 starts, point-to-plane ICP). Does nothing if `out` is null.
///
/// # Safety
/// `out` must be null or point to a writable `PcrnetOptions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_options_default(out: *mut PcrnetOptions) {
    if !out.is_null() {
        // SAFETY: non-null and the caller's contract.
        unsafe { out.write(Options::default().into()) };
    }
}

/// Writes the recommended options with the steps `model` was trained for
/// (`Int8Model::trained_options`): its passes (PCRNet 1, i-PCRNet more),
/// or for a model trained as PointNetLK, which has no head, `passes` 0,
/// its LK steps in `lk_iterations` and its larger sample in
/// `network_points` (256 against 128); and `max_residual` calibrated by
/// the template's residual floor when the blob carries one
/// (`pcrnet_model_residual_floor`). `PCRNET_ERROR_NULL_POINTER` or
/// `PCRNET_ERROR_NOT_LOADED`, writing nothing, otherwise.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`; `out` null or point
/// to a writable `PcrnetOptions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_options_for_model(
    model: *const PcrnetModel,
    out: *mut PcrnetOptions,
) -> PcrnetStatus {
    if out.is_null() {
        return PcrnetStatus::PCRNET_ERROR_NULL_POINTER;
    }
    match self::model(model) {
        Ok(m) => {
            // SAFETY: non-null and the caller's contract.
            unsafe { out.write(m.trained_options().into()) };
            PcrnetStatus::PCRNET_OK
        }
        Err(status) => status,
    }
}

/// Writes the options of the network alone, scored: one start, no ICP.
/// Does nothing if `out` is null.
///
/// # Safety
/// `out` must be null or point to a writable `PcrnetOptions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_options_network_only(out: *mut PcrnetOptions) {
    if !out.is_null() {
        // SAFETY: non-null and the caller's contract.
        unsafe { out.write(Options::network_only().into()) };
    }
}

/// Registers `n_points` source points (`x y z` each, source units) to the
/// model's template: network, flip resolution, ICP and residuals, as
/// `options` say. Writes `out` on success.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`; `points` to
/// `3 * n_points` readable floats (or null); `options` to a
/// `PcrnetOptions` (or null); `scratch` to `scratch_len` writable bytes
/// (or null) overlapping none of the others; `out` to a writable
/// `PcrnetRegistration` (or null).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_register(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    options: *const PcrnetOptions,
    scratch: *mut i8,
    scratch_len: usize,
    out: *mut PcrnetRegistration,
) -> PcrnetStatus {
    let m = match self::model(model) {
        Ok(m) => m,
        Err(s) => return s,
    };
    // SAFETY: the caller's contract for every pointer.
    unsafe {
        register_into(points, n_points, options, out, |source, options| {
            let scratch = scratch_mut(scratch, scratch_len)?;
            Ok(m.register(source, options, scratch)?)
        })
    }
}

/// What `pcrnet_register` and `pcrnet_prepared_register` share around
/// `call` (the registration itself): `options` and `out` checked, the
/// options and points converted, `out` written on success.
///
/// # Safety
/// `points`, `options` and `out` as `pcrnet_register` says.
unsafe fn register_into(
    points: *const f32,
    n_points: usize,
    options: *const PcrnetOptions,
    out: *mut PcrnetRegistration,
    call: impl FnOnce(&[[f32; 3]], &Options) -> Result<Registration, PcrnetStatus>,
) -> PcrnetStatus {
    let run = || -> Result<PcrnetRegistration, PcrnetStatus> {
        if options.is_null() || out.is_null() {
            return Err(PCRNET_ERROR_NULL_POINTER);
        }
        // SAFETY: non-null and the caller's contract.
        let options = Options::try_from(unsafe { &*options })?;
        // SAFETY: the caller's contract for `points`.
        let source = unsafe { cloud(points, n_points)? };
        Ok((&call(source, &options)?).into())
    };
    match run() {
        Ok(r) => {
            // SAFETY: checked non-null above; the caller's contract.
            unsafe { out.write(r) };
            PCRNET_OK
        }
        Err(s) => s,
    }
}

/// The network alone (no check, no refinement): up to `passes` passes
/// (1: PCRNet; more: i-PCRNet, composing the estimates, stopping once a
/// pass moves the pose by less than `tolerance`), each on at most 128
/// points of the cloud (`NETWORK_POINTS`; every k-th, the sample a
/// registration's pass takes). Writes the pose `[qw, qx, qy, qz, tx, ty, tz]` (source units)
/// to `pose` and the passes run to `passes_run` on success.
///
/// # Safety
/// As `pcrnet_register`; `pose` must point to 7 writable floats and
/// `passes_run` to a writable `uint32_t` (or be null).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_network_pose(
    model: *const PcrnetModel,
    points: *const f32,
    n_points: usize,
    passes: u32,
    tolerance: f32,
    scratch: *mut i8,
    scratch_len: usize,
    pose: *mut f32,
    passes_run: *mut u32,
) -> PcrnetStatus {
    let m = match self::model(model) {
        Ok(m) => m,
        Err(s) => return s,
    };
    // SAFETY: the caller's contract for every pointer.
    unsafe {
        network_pose_into(points, n_points, pose, passes_run, |source| {
            let scratch = scratch_mut(scratch, scratch_len)?;
            Ok(m.network_pose(source, passes as usize, tolerance, scratch)?)
        })
    }
}

/// What `pcrnet_network_pose` and `pcrnet_prepared_network_pose` share
/// around `call` (the passes themselves): `pose` and `passes_run`
/// checked, the points converted, the pose and the passes run written on
/// success.
///
/// # Safety
/// `points`, `pose` and `passes_run` as `pcrnet_network_pose` says.
unsafe fn network_pose_into(
    points: *const f32,
    n_points: usize,
    pose: *mut f32,
    passes_run: *mut u32,
    call: impl FnOnce(&[[f32; 3]]) -> Result<(Pose, usize), PcrnetStatus>,
) -> PcrnetStatus {
    let run = || -> Result<([f32; 7], u32), PcrnetStatus> {
        if pose.is_null() || passes_run.is_null() {
            return Err(PCRNET_ERROR_NULL_POINTER);
        }
        if !(pose as usize).is_multiple_of(align_of::<f32>()) {
            return Err(PCRNET_ERROR_MISALIGNED);
        }
        // SAFETY: the caller's contract for `points`.
        let source = unsafe { cloud(points, n_points)? };
        let (p, n) = call(source)?;
        let mut out = [0f32; 7];
        out[..4].copy_from_slice(&p.rotation);
        out[4..].copy_from_slice(&p.translation);
        Ok((out, u32::try_from(n).unwrap_or(u32::MAX)))
    };
    match run() {
        Ok((p, n)) => {
            // SAFETY: checked non-null and aligned above; the caller's contract.
            unsafe {
                core::ptr::copy_nonoverlapping(p.as_ptr(), pose, 7);
                passes_run.write(n);
            }
            PCRNET_OK
        }
        Err(s) => s,
    }
}

/// Whether `len` elements of `T` fit in one allocation (`isize::MAX`
/// bytes); a length that cannot is [`PCRNET_ERROR_INVALID_OPTION`].
fn addressable<T>(len: usize) -> Result<(), PcrnetStatus> {
    match len.checked_mul(size_of::<T>()) {
        Some(bytes) if bytes <= isize::MAX as usize => Ok(()),
        _ => Err(PCRNET_ERROR_INVALID_OPTION),
    }
}

/// `n_points` points of 3 floats at `points`.
///
/// # Safety
/// As [`slice`] for `3 * n_points` floats.
unsafe fn cloud<'a>(points: *const f32, n_points: usize) -> Result<&'a [[f32; 3]], PcrnetStatus> {
    // SAFETY: [f32; 3] has the alignment of f32; the caller's contract.
    unsafe { slice(points as *const [f32; 3], n_points) }
}

/// `len` writable elements at `ptr`; null with `len > 0` is an error, and
/// so is a pointer not aligned for `T`.
///
/// # Safety
/// If non-null, `ptr` must point to `len` writable `T` nothing else uses
/// during the call.
unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize) -> Result<&'a mut [T], PcrnetStatus> {
    if len == 0 {
        return Ok(&mut []);
    }
    addressable::<T>(len)?;
    if ptr.is_null() {
        return Err(PCRNET_ERROR_NULL_POINTER);
    }
    if !(ptr as usize).is_multiple_of(align_of::<T>()) {
        return Err(PCRNET_ERROR_MISALIGNED);
    }
    // SAFETY: non-null, aligned, and the caller's contract above.
    Ok(unsafe { core::slice::from_raw_parts_mut(ptr, len) })
}

/// The scratch buffer; null with a non-zero length is an error.
///
/// # Safety
/// As [`slice_mut`] for `len` bytes.
unsafe fn scratch_mut<'a>(scratch: *mut i8, len: usize) -> Result<&'a mut [i8], PcrnetStatus> {
    // SAFETY: the caller's contract.
    unsafe { slice_mut(scratch, len) }
}

/// What a status means and what to do, as a NUL-terminated string in
/// static memory; an unknown value gives "unknown status".
#[unsafe(no_mangle)]
pub extern "C" fn pcrnet_status_message(status: i32) -> *const c_char {
    let text: &'static core::ffi::CStr = match status {
        0 => c"success",
        -1 => c"a required pointer is null",
        -2 => c"an array is not aligned for its type: points and floats need 4-byte alignment, depth values and labels 2-byte",
        -3 => c"the model handle is not loaded: call pcrnet_model_load and check its status",
        -4 => c"the prepared handle is not prepared: call pcrnet_prepare (again after loading its model handle again) and check its status",
        -10 => c"not a model blob: magic bytes PCRN missing",
        -11 => c"unsupported model format version: re-export the model with `pcrnet export` (or `pcrnet upgrade` a version-2 f32 blob); a blob newer than this library needs a later library",
        -12 => c"the blob holds another kind of model: the C API loads int8 blobs (`pcrnet export` writes one)",
        -13 => c"model blob truncated: flash the whole file",
        -14 => c"unexpected bytes after the model blob's CRC: pass the blob's exact length",
        -15 => c"model blob CRC mismatch: the blob is damaged; flash it again",
        -16 => c"model payload does not decode",
        -17 => c"inconsistent model dimensions",
        -18 => c"a model parameter is outside its documented range",
        -20 => c"scratch too small: give at least pcrnet_model_scratch_len(model, 1) bytes",
        -21 => c"output buffer too small",
        -30 => c"the point cloud is empty",
        -31 => c"a point has a NaN or infinite coordinate",
        -32 => c"every point the network encodes lies outside the model's input range: the cloud is in other units than the template, or far from where the template is; bring it into the template's units and frame",
        -33 => c"the network's output has a zero quaternion",
        -34 => c"the pose or residual is not finite: the coordinates are too large once moved into the model's frame",
        -40 => c"a registration option is out of range (zero passes with zero lk_iterations, zero hypotheses, max_points or network_points, a negative or non-finite tolerance or distance, an unknown metric, or more points or buffer elements than memory can hold)",
        -41 => c"a pose given as input (to track from, or to check) is not finite or its quaternion is not of unit length: pass the pose a registration or tracking step wrote, or call pcrnet_register",
        -42 => c"the depth frame or a scene setting cannot be used (a zero size or stride, a frame buffer shorter than height x stride, intrinsics or a depth scale not finite and positive, a step of 0 or a sampling grid of more cells than its labels can number): check the camera's intrinsics and the frame's dimensions, or raise the grid step",
        -43 => c"this blob has no head (a model trained as PointNetLK): set passes to 0 and lk_iterations to its trained count (pcrnet_model_trained_passes)",
        -44 => c"lk_iterations needs PointNetLK's solver in the blob: export the model with `pcrnet export --lk`, or set lk_iterations to 0",
        -99 => c"an error this version of the C API has no code for: update the library",
        _ => c"unknown status",
    };
    text.as_ptr()
}

/// The static library's panic handler on bare-metal targets. No panic is
/// reachable from any input: with the `prove-no-panic` feature the handler
/// calls a function that exists nowhere, so linking a firmware that calls
/// this API fails if a panic path survived optimisation (`cargo xtask
/// no-panic` does this for every function here and in `pcrnet-core`).
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    #[cfg(feature = "prove-no-panic")]
    {
        unsafe extern "C" {
            /// Defined nowhere: referencing it fails the link.
            fn pcrnet_core_can_panic() -> !;
        }
        // SAFETY: never runs; the link fails first if this is reachable.
        unsafe { pcrnet_core_can_panic() }
    }
    #[cfg(not(feature = "prove-no-panic"))]
    loop {
        core::hint::spin_loop();
    }
}
