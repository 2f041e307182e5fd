//! `pcrnet_track` as C calls it: bit-identical to the Rust API's
//! `Int8Model::track`, kept and recovered outcomes, and a status with
//! nothing written for a null or misaligned previous pose or outcome, and
//! for a previous pose that is not a pose.
#![allow(unsafe_code)]

mod common;

use common::{loaded, options_default, sentinel, shipped_blob, shipped_source};
use pcrnet::*;
use pcrnet_core::{Int8Model, Options, Pose, TrackOutcome};

/// `pcrnet_track` on `points` from `previous`: status, result, outcome
/// (7 if not written).
fn track(
    model: &PcrnetModel,
    points: &[[f32; 3]],
    previous: *const f32,
    scratch: &mut [i8],
) -> (PcrnetStatus, PcrnetRegistration, u32) {
    let (mut out, mut outcome) = (sentinel(), 7u32);
    let options = options_default();
    let status = unsafe {
        pcrnet_track(
            model,
            points.as_ptr() as *const f32,
            points.len(),
            previous,
            &options,
            scratch.as_mut_ptr(),
            scratch.len(),
            &mut out,
            &mut outcome,
        )
    };
    (status, out, outcome)
}

fn flat(p: &Pose) -> [f32; 7] {
    let (q, t) = (p.rotation, p.translation);
    [q[0], q[1], q[2], q[3], t[0], t[1], t[2]]
}

#[test]
fn tracking_through_the_c_api_is_bit_identical_to_the_rust_api() {
    let blob = shipped_blob();
    let (handle, source) = (loaded(&blob), shipped_source());
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let mut scratch = vec![0i8; rust.scratch_len(1)];
    let registered = rust
        .register(&source, &Options::default(), &mut scratch)
        .unwrap();
    // From the registered pose (kept) and from the identity, far from it
    // (the full registration, recovered).
    for (previous, outcome, code) in [
        (registered.pose, TrackOutcome::Kept, PCRNET_TRACK_KEPT),
        (
            Pose::IDENTITY,
            TrackOutcome::Recovered,
            PCRNET_TRACK_RECOVERED,
        ),
    ] {
        let want = rust
            .track(&source, &previous, &Options::default(), &mut scratch)
            .unwrap();
        assert_eq!(want.outcome, outcome);
        let (status, got, what) = track(&handle, &source, flat(&previous).as_ptr(), &mut scratch);
        assert_eq!(status, PcrnetStatus::PCRNET_OK);
        assert_eq!(what, code);
        assert_eq!(got, PcrnetRegistration::from(&want.registration));
    }
}

#[test]
fn bad_previous_poses_and_outputs_are_statuses_and_write_nothing() {
    let blob = shipped_blob();
    let (handle, source) = (loaded(&blob), shipped_source());
    let mut scratch = vec![0i8; Int8Model::from_bytes(&blob).unwrap().scratch_len(1)];
    let untouched = |(status, out, outcome): (PcrnetStatus, PcrnetRegistration, u32)| {
        assert_eq!(out, sentinel());
        assert_eq!(outcome, 7);
        status
    };
    let null = track(&handle, &source, std::ptr::null(), &mut scratch);
    assert_eq!(untouched(null), PcrnetStatus::PCRNET_ERROR_NULL_POINTER);
    let identity = flat(&Pose::IDENTITY);
    let (outcome, mut out) = (7u32, sentinel());
    let options = options_default();
    let status = unsafe {
        pcrnet_track(
            &*handle,
            source.as_ptr() as *const f32,
            source.len(),
            identity.as_ptr(),
            &options,
            scratch.as_mut_ptr(),
            scratch.len(),
            &mut out,
            std::ptr::null_mut(),
        )
    };
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_NULL_POINTER);
    assert_eq!((out, outcome), (sentinel(), 7));
    // Seven floats one byte in: misaligned.
    let bytes = [0u8; 4 * 8 + 1];
    let misaligned = bytes
        .as_ptr()
        .wrapping_add(1 + bytes.as_ptr().align_offset(4)) as *const f32;
    let status = untouched(track(&handle, &source, misaligned, &mut scratch));
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_MISALIGNED);
    for bad in [
        [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0],
    ] {
        let status = untouched(track(&handle, &source, bad.as_ptr(), &mut scratch));
        assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_POSE);
    }
}
