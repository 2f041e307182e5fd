//! A model made ready once for many calls on one scratch
//! (`pcrnet-core`'s `Int8Model::prepare`): on an x86-64 or aarch64 host
//! the block kernel's weight copies and the head's folded template half
//! are made once instead of per call; elsewhere nothing is prepared and
//! the calls are `pcrnet_register`'s and `pcrnet_network_pose`'s. Results
//! are the same, bit for bit.

use core::mem::{align_of, size_of};

use pcrnet_core::Prepared;

use super::PcrnetStatus::{self, *};
use super::{
    PcrnetModel, PcrnetOptions, PcrnetRegistration, network_pose_into, register_into, scratch_mut,
};

/// Storage words of a `PcrnetPrepared` (8 bytes each; 64 bytes on every
/// target, checked at compile time).
pub const PCRNET_PREPARED_WORDS: usize = 8;

/// Bytes of a `PcrnetPrepared` (`8 * PCRNET_PREPARED_WORDS`), for C code
/// to check its view of the type with `_Static_assert`.
pub const PCRNET_PREPARED_SIZE: usize = 64;

const _: () = assert!(size_of::<PcrnetPrepared>() == PCRNET_PREPARED_SIZE);
const _: () = assert!(PCRNET_PREPARED_SIZE == 8 * PCRNET_PREPARED_WORDS);

/// A model handle and a scratch made ready by `pcrnet_prepare`: storage
/// the caller owns. Its contents are private; its size and 8-byte
/// alignment are fixed on every target.
#[repr(C)]
pub struct PcrnetPrepared {
    storage: [u64; PCRNET_PREPARED_WORDS],
}

impl PcrnetPrepared {
    /// A handle that is not prepared yet (all zeros, as a C `static` is).
    pub const fn new() -> Self {
        PcrnetPrepared {
            storage: [0; PCRNET_PREPARED_WORDS],
        }
    }
}

impl Default for PcrnetPrepared {
    fn default() -> Self {
        Self::new()
    }
}

/// Marks a handle filled by `pcrnet_prepare` (first storage word).
const PREPARED: u64 = 0x5043_524e_5052_4550; // "PCRNPREP"

/// Byte offset of the Rust value inside the handle: after the marker.
const PREPARED_AT: usize = 8;

type Ready = Prepared<'static, 'static, 'static>;

const _: () = assert!(PREPARED_AT + size_of::<Ready>() <= size_of::<PcrnetPrepared>());
const _: () = assert!(align_of::<Ready>() <= align_of::<PcrnetPrepared>());

/// The prepared model a filled handle holds, or a status.
fn prepared(handle: *mut PcrnetPrepared) -> Result<&'static mut Ready, PcrnetStatus> {
    if handle.is_null() {
        return Err(PCRNET_ERROR_NULL_POINTER);
    }
    // SAFETY: non-null, and a PcrnetPrepared is always readable as its u64
    // words (the C type has the same size and alignment).
    if unsafe { (*handle).storage[0] } != PREPARED {
        return Err(PCRNET_ERROR_NOT_PREPARED);
    }
    // SAFETY: the marker is written only by pcrnet_prepare right after it
    // stored a valid Prepared at PREPARED_AT (in bounds and aligned, by the
    // const asserts above). The model handle, its blob and the scratch it
    // borrows outlive the handle, unused by other calls, by the API's
    // contract ("'static" stands for that).
    Ok(unsafe { &mut *((handle as *mut u8).add(PREPARED_AT) as *mut Ready) })
}

/// Makes `scratch` ready for many calls of `model` and fills `prepared`.
/// `pcrnet_model_host_scratch_len` bytes let a host prepare everything;
/// at least `pcrnet_model_scratch_len(model, 1)` are needed. Until the
/// last call on `prepared`, the model handle, its blob and the scratch
/// must stay valid and unchanged, and the scratch must be used by no other
/// call; after `pcrnet_model_load` on the same model handle, prepare
/// again. On failure `prepared` is marked not prepared.
///
/// # Safety
/// `model` must be null or point to a `PcrnetModel`; `scratch` to
/// `scratch_len` writable bytes (or null) overlapping nothing else;
/// `prepared` to writable storage of a `PcrnetPrepared` (or be null).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_prepare(
    model: *const PcrnetModel,
    scratch: *mut i8,
    scratch_len: usize,
    prepared: *mut PcrnetPrepared,
) -> PcrnetStatus {
    if prepared.is_null() {
        return PCRNET_ERROR_NULL_POINTER;
    }
    // SAFETY: non-null and the caller's contract: the storage is writable.
    unsafe { (*prepared).storage[0] = 0 };
    let m = match super::model(model) {
        Ok(m) => m,
        Err(s) => return s,
    };
    // SAFETY: the caller's contract: the scratch stays the handle's alone.
    let scratch: &'static mut [i8] = match unsafe { scratch_mut(scratch, scratch_len) } {
        Ok(s) => s,
        Err(s) => return s,
    };
    match m.prepare(scratch) {
        Ok(p) => {
            // SAFETY: in bounds and aligned (const asserts above); the
            // storage is plain words, so overwriting needs no drop.
            unsafe {
                core::ptr::write((prepared as *mut u8).add(PREPARED_AT) as *mut Ready, p);
                (*prepared).storage[0] = PREPARED;
            }
            PCRNET_OK
        }
        Err(e) => e.into(),
    }
}

/// `pcrnet_register` on a prepared handle (its model and scratch).
///
/// # Safety
/// `prepared` must be null or point to a `PcrnetPrepared` whose model
/// handle and scratch are still valid (see `pcrnet_prepare`); `points`,
/// `options` and `out` as `pcrnet_register` says.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_prepared_register(
    prepared: *mut PcrnetPrepared,
    points: *const f32,
    n_points: usize,
    options: *const PcrnetOptions,
    out: *mut PcrnetRegistration,
) -> PcrnetStatus {
    let p = match self::prepared(prepared) {
        Ok(p) => p,
        Err(s) => return s,
    };
    // SAFETY: the caller's contract for every pointer.
    unsafe {
        register_into(points, n_points, options, out, |source, options| {
            Ok(p.register(source, options)?)
        })
    }
}

/// `pcrnet_network_pose` on a prepared handle (its model and scratch).
///
/// # Safety
/// As `pcrnet_prepared_register` for `prepared` and `points`; `pose` and
/// `passes_run` as `pcrnet_network_pose` says.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pcrnet_prepared_network_pose(
    prepared: *mut PcrnetPrepared,
    points: *const f32,
    n_points: usize,
    passes: u32,
    tolerance: f32,
    pose: *mut f32,
    passes_run: *mut u32,
) -> PcrnetStatus {
    let p = match self::prepared(prepared) {
        Ok(p) => p,
        Err(s) => return s,
    };
    // SAFETY: the caller's contract for every pointer.
    unsafe {
        network_pose_into(points, n_points, pose, passes_run, |source| {
            Ok(p.network_pose(source, passes as usize, tolerance)?)
        })
    }
}
