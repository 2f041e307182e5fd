//! `pcrnet_feature_distance` as C calls it: bit-identical to the Rust
//! API's `Int8Model::feature_distance`, and a status with nothing written
//! for null, misaligned or non-finite input.
#![allow(unsafe_code)]

mod common;

use common::{loaded, options_default, sentinel, shipped_blob, shipped_source};
use pcrnet::*;
use pcrnet_core::{Int8Model, Options};

/// `pcrnet_feature_distance` of `points` moved by `pose`: status and the
/// distance (-1 if not written).
fn distance(
    model: &PcrnetModel,
    points: &[[f32; 3]],
    pose: *const f32,
    scratch: &mut [i8],
) -> (PcrnetStatus, f32) {
    let mut out = -1.0f32;
    let status = unsafe {
        pcrnet_feature_distance(
            model,
            points.as_ptr() as *const f32,
            points.len(),
            pose,
            scratch.as_mut_ptr(),
            scratch.len(),
            &mut out,
        )
    };
    (status, out)
}

#[test]
fn the_feature_check_through_the_c_api_is_bit_identical_to_the_rust_api() {
    let blob = shipped_blob();
    let (handle, source) = (loaded(&blob), shipped_source());
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let mut scratch = vec![0i8; rust.scratch_len(1)];
    let r = rust
        .register(&source, &Options::default(), &mut scratch)
        .unwrap();
    let want = rust
        .feature_distance(&source, &r.pose, &mut scratch)
        .unwrap();
    // The pose as C gets it from `pcrnet_register`.
    let mut registered = sentinel();
    let status = unsafe {
        pcrnet_register(
            &*handle,
            source.as_ptr() as *const f32,
            source.len(),
            &options_default(),
            scratch.as_mut_ptr(),
            scratch.len(),
            &mut registered,
        )
    };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    let (q, t) = (registered.rotation, registered.translation);
    let pose = [q[0], q[1], q[2], q[3], t[0], t[1], t[2]];
    assert_eq!(pose[..4], r.pose.rotation);
    let (status, got) = distance(&handle, &source, pose.as_ptr(), &mut scratch);
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert_eq!(got.to_bits(), want.to_bits());
    // The registered pose (an exact fit of the demo source) lies far
    // nearer the template in feature space than the same pose turned a
    // quarter about z. (Not near 0: the shipped blob's stored feature pools
    // all 512 template points, the check a sample of 128; models/README.md.)
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let turn = pcrnet_core::Pose {
        rotation: [h, 0.0, 0.0, h],
        translation: [0.0; 3],
    };
    let wrong = rust
        .feature_distance(&source, &r.pose.then(&turn), &mut scratch)
        .unwrap();
    assert!(
        want < 0.5 * wrong,
        "the registered pose {want} against a turned one {wrong}"
    );

    // Nothing written on a bad call.
    let (status, got) = distance(&handle, &source, std::ptr::null(), &mut scratch);
    assert_eq!(
        (status, got),
        (PcrnetStatus::PCRNET_ERROR_NULL_POINTER, -1.0)
    );
    let nan = [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let (status, got) = distance(&handle, &source, nan.as_ptr(), &mut scratch);
    assert_eq!(
        (status, got),
        (PcrnetStatus::PCRNET_ERROR_NON_FINITE_RESULT, -1.0)
    );
    let floats = [0f32; 8];
    let misaligned = unsafe { (floats.as_ptr() as *const u8).add(1) } as *const f32;
    let (status, _) = distance(&handle, &source, misaligned, &mut scratch);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_MISALIGNED);
    let (status, got) = distance(&handle, &[], pose.as_ptr(), &mut scratch);
    assert_eq!(
        (status, got),
        (PcrnetStatus::PCRNET_ERROR_EMPTY_CLOUD, -1.0)
    );
}
