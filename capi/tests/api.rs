//! The C API called as C calls it: every pointer check gives its status,
//! nothing is written on failure, and a registration through the C API is
//! bit-identical to `pcrnet_core`'s.
#![allow(unsafe_code)]

use core::ffi::CStr;
use std::mem::MaybeUninit;

mod common;

use common::{loaded, models, options_default, sentinel, shipped_blob, shipped_source};
use pcrnet::*;
use pcrnet_core::{Int8Model, Options};

fn zeroed_model() -> Box<PcrnetModel> {
    unsafe { Box::<MaybeUninit<PcrnetModel>>::new(MaybeUninit::zeroed()).assume_init() }
}

fn register(
    model: &PcrnetModel,
    points: &[[f32; 3]],
    options: &PcrnetOptions,
    scratch: &mut [i8],
) -> (PcrnetStatus, PcrnetRegistration) {
    let mut out = sentinel();
    let status = unsafe {
        pcrnet_register(
            model,
            points.as_ptr() as *const f32,
            points.len(),
            options,
            scratch.as_mut_ptr(),
            scratch.len(),
            &mut out,
        )
    };
    (status, out)
}

#[test]
fn registration_through_the_c_api_is_bit_identical_to_the_rust_api() {
    let blob = shipped_blob();
    let model = loaded(&blob);
    let source = shipped_source();
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let scratch_len = unsafe { pcrnet_model_scratch_len(&*model, PCRNET_MAX_TILE) };
    assert_eq!(scratch_len, rust.scratch_len(PCRNET_MAX_TILE));
    assert_eq!(
        unsafe { pcrnet_model_trained_passes(&*model) } as usize,
        rust.trained_passes()
    );
    let mut scratch = vec![0i8; scratch_len];
    for options in [Options::default(), Options::network_only()] {
        let c_options = PcrnetOptions::from(options);
        let (status, c) = register(&model, &source, &c_options, &mut scratch);
        assert_eq!(status, PcrnetStatus::PCRNET_OK);
        let r = rust.register(&source, &options, &mut scratch).unwrap();
        // Field by field, as bits: the C layer only converts types.
        assert_eq!(c, PcrnetRegistration::from(&r));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&c.rotation), bits(&r.pose.rotation));
        assert_eq!(bits(&c.translation), bits(&r.pose.translation));
        assert_eq!(c.plane_residual.to_bits(), r.plane_residual.to_bits());
    }
    // Network alone, iterated.
    let mut pose = [0f32; 7];
    let mut passes = 0u32;
    let status = unsafe {
        pcrnet_network_pose(
            &*model,
            source.as_ptr() as *const f32,
            source.len(),
            3,
            0.0,
            scratch.as_mut_ptr(),
            scratch.len(),
            pose.as_mut_ptr(),
            &mut passes,
        )
    };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    let (p, n) = rust.network_pose(&source, 3, 0.0, &mut scratch).unwrap();
    assert_eq!(passes as usize, n);
    assert_eq!(pose[..4], p.rotation);
    assert_eq!(pose[4..], p.translation);
}

/// PointNetLK through the C API: a blob without a head (the shipped
/// encoder with a random solver: agreement, not accuracy) registers by
/// `lk_iterations` bit for bit as the Rust API does, a network pass asked
/// of it is `PCRNET_ERROR_NO_HEAD`, and LK steps asked of the shipped blob
/// (no solver) are `PCRNET_ERROR_NO_LK_SOLVER`.
#[test]
fn pointnetlk_through_the_c_api() {
    let shipped = shipped_blob();
    let (mut arena, mut out) = (vec![0u8; 1 << 16], vec![0u8; shipped.len()]);
    let blob = pcrnet_core::testing::with_random_lk_solver(&shipped, 3, true, &mut arena, &mut out)
        .unwrap()
        .to_vec();
    let model = loaded(&blob);
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let source = shipped_source();
    let mut scratch = vec![0i8; rust.scratch_len(PCRNET_MAX_TILE)];
    let lk = Options {
        passes: 0,
        lk_iterations: 3,
        ..Options::default()
    };
    // The options for the model: no network pass, its trained LK steps.
    let mut for_model = options_default();
    let status = unsafe { pcrnet_options_for_model(&*model, &mut for_model) };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert_eq!(for_model, PcrnetOptions::from(rust.trained_options()));
    assert_eq!(
        (for_model.passes, for_model.lk_iterations),
        (0, rust.trained_passes() as u32)
    );
    let (status, c) = register(&model, &source, &PcrnetOptions::from(lk), &mut scratch);
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    let r = rust.register(&source, &lk, &mut scratch).unwrap();
    assert_eq!(c, PcrnetRegistration::from(&r));
    assert_eq!((c.passes, c.lk_iterations), (0, 3));
    let (status, c) = register(&model, &source, &options_default(), &mut scratch);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_NO_HEAD);
    assert_eq!(c, sentinel());
    let plain = loaded(&shipped);
    let (status, _) = register(&plain, &source, &PcrnetOptions::from(lk), &mut scratch);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_NO_LK_SOLVER);
}

#[test]
fn the_smallest_scratch_gives_the_same_registration() {
    let blob = shipped_blob();
    let model = loaded(&blob);
    let source = shipped_source();
    let options = options_default();
    let mut small = vec![0i8; unsafe { pcrnet_model_scratch_len(&*model, 1) }];
    let mut big = vec![0i8; unsafe { pcrnet_model_scratch_len(&*model, PCRNET_MAX_TILE) }];
    assert!(small.len() < big.len());
    let (s1, r1) = register(&model, &source, &options, &mut small);
    let (s2, r2) = register(&model, &source, &options, &mut big);
    assert_eq!((s1, s2), (PcrnetStatus::PCRNET_OK, PcrnetStatus::PCRNET_OK));
    assert_eq!(r1, r2);
    // The host scratch (the AVX2 block kernel where the CPU has it).
    let mut host = vec![0i8; unsafe { pcrnet_model_host_scratch_len(&*model) }];
    assert!(host.len() > big.len());
    let (s3, r3) = register(&model, &source, &options, &mut host);
    assert_eq!(s3, PcrnetStatus::PCRNET_OK);
    assert_eq!(r1, r3);
    // One byte short of the minimum is refused, and nothing is written.
    let (s, out) = register(&model, &source, &options, &mut small[1..]);
    assert_eq!(s, PcrnetStatus::PCRNET_ERROR_SCRATCH_TOO_SMALL);
    assert_eq!(out, sentinel());
}

#[test]
fn null_pointers_and_unloaded_handles_are_statuses_and_write_nothing() {
    use PcrnetStatus::*;
    let blob = shipped_blob();
    let model = loaded(&blob);
    let source = shipped_source();
    let options = options_default();
    let mut scratch = vec![0i8; unsafe { pcrnet_model_scratch_len(&*model, 1) }];
    let points = source.as_ptr() as *const f32;
    let call = |model: *const PcrnetModel,
                points: *const f32,
                n: usize,
                options: *const PcrnetOptions,
                scratch: *mut i8,
                len: usize,
                out: *mut PcrnetRegistration| unsafe {
        pcrnet_register(model, points, n, options, scratch, len, out)
    };
    let s = scratch.as_mut_ptr();
    let len = scratch.len();
    let mut out = sentinel();
    let o = &mut out as *mut PcrnetRegistration;
    let m = &*model as *const PcrnetModel;
    let null_f = std::ptr::null::<f32>();
    assert_eq!(
        call(std::ptr::null(), points, 512, &options, s, len, o),
        PCRNET_ERROR_NULL_POINTER
    );
    assert_eq!(
        call(m, null_f, 512, &options, s, len, o),
        PCRNET_ERROR_NULL_POINTER
    );
    assert_eq!(
        call(m, points, 512, std::ptr::null(), s, len, o),
        PCRNET_ERROR_NULL_POINTER
    );
    assert_eq!(
        call(m, points, 512, &options, std::ptr::null_mut(), len, o),
        PCRNET_ERROR_NULL_POINTER
    );
    assert_eq!(
        call(m, points, 512, &options, s, len, std::ptr::null_mut()),
        PCRNET_ERROR_NULL_POINTER
    );
    // A null point array with no points is an empty cloud, not a crash.
    assert_eq!(
        call(m, null_f, 0, &options, s, len, o),
        PCRNET_ERROR_EMPTY_CLOUD
    );
    // Points one byte off their alignment.
    let bytes: Vec<u8> = vec![0; 13];
    let odd = bytes
        .as_ptr()
        .wrapping_add(1 + bytes.as_ptr().align_offset(4)) as *const f32;
    assert_eq!(
        call(m, odd, 1, &options, s, len, o),
        PCRNET_ERROR_MISALIGNED
    );
    // A point count whose byte size overflows.
    assert_eq!(
        call(m, points, usize::MAX / 4, &options, s, len, o),
        PCRNET_ERROR_INVALID_OPTION
    );
    // A handle never loaded, and one whose load failed.
    let blank = zeroed_model();
    assert_eq!(
        call(&*blank, points, 512, &options, s, len, o),
        PCRNET_ERROR_NOT_LOADED
    );
    let mut failed = loaded(&blob);
    let status = unsafe { pcrnet_model_load(blob.as_ptr(), 3, &mut *failed) };
    assert_eq!(status, PCRNET_ERROR_TRUNCATED);
    assert_eq!(
        call(&*failed, points, 512, &options, s, len, o),
        PCRNET_ERROR_NOT_LOADED
    );
    assert_eq!(unsafe { pcrnet_model_scratch_len(&*failed, 1) }, 0);
    assert_eq!(unsafe { pcrnet_model_host_scratch_len(&*failed) }, 0);
    assert_eq!(unsafe { pcrnet_model_scratch_len(m, 0) }, 0);
    assert_eq!(
        unsafe { pcrnet_model_scratch_len(m, PCRNET_MAX_TILE + 1) },
        0
    );
    assert_eq!(unsafe { pcrnet_model_trained_passes(std::ptr::null()) }, 0);
    assert_eq!(
        unsafe { pcrnet_model_load(blob.as_ptr(), blob.len(), std::ptr::null_mut()) },
        PCRNET_ERROR_NULL_POINTER
    );
    assert_eq!(out, sentinel(), "a failed call wrote its output");
    unsafe {
        pcrnet_options_default(std::ptr::null_mut());
        pcrnet_options_network_only(std::ptr::null_mut());
    }
}

#[test]
fn bad_blobs_bad_clouds_and_bad_options_get_their_own_status() {
    use PcrnetStatus::*;
    let blob = shipped_blob();
    let mut handle = zeroed_model();
    let load = |bytes: &[u8], handle: &mut PcrnetModel| unsafe {
        pcrnet_model_load(bytes.as_ptr(), bytes.len(), handle)
    };
    let mut wrong_magic = blob.clone();
    wrong_magic[0] ^= 0xff;
    assert_eq!(load(&wrong_magic, &mut handle), PCRNET_ERROR_BAD_MAGIC);
    let mut flipped = blob.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 1;
    assert_eq!(load(&flipped, &mut handle), PCRNET_ERROR_BAD_CRC);
    let mut longer = blob.clone();
    longer.push(0);
    assert_eq!(load(&longer, &mut handle), PCRNET_ERROR_TRAILING_DATA);
    assert_eq!(load(&[], &mut handle), PCRNET_ERROR_TRUNCATED);
    let f32_blob = std::fs::read(models().join("embedded-default-f32.pcrn")).unwrap();
    assert_eq!(load(&f32_blob, &mut handle), PCRNET_ERROR_WRONG_KIND);

    let model = loaded(&blob);
    let mut scratch = vec![0i8; unsafe { pcrnet_model_scratch_len(&*model, 1) }];
    let options = options_default();
    let mut cloud = shipped_source();
    cloud[3][1] = f32::NAN;
    let (s, _) = register(&model, &cloud, &options, &mut scratch);
    assert_eq!(s, PCRNET_ERROR_NON_FINITE_COORDINATE);
    // A stray point the network samples (every other point of the 512 at
    // the default network_points) is left out and counted; a cloud with
    // no point in range has no pose.
    cloud[3] = shipped_source()[3];
    cloud[4][1] = 1e9;
    let (s, r) = register(&model, &cloud, &options, &mut scratch);
    assert_eq!((s, r.out_of_range), (PCRNET_OK, 1));
    let far = [
        [1e9f32, 0.0, 0.0],
        [-1e9, 0.0, 0.0],
        [0.0, 1e9, 0.0],
        [0.0, -1e9, 0.0],
    ];
    let (s, _) = register(&model, &far, &options, &mut scratch);
    assert_eq!(s, PCRNET_ERROR_NO_POINT_IN_RANGE);

    let source = shipped_source();
    for bad in [
        PcrnetOptions {
            metric: 2,
            ..options
        },
        PcrnetOptions {
            passes: 0,
            ..options
        },
        PcrnetOptions {
            network_points: 0,
            ..options
        },
        PcrnetOptions {
            icp_distance: f32::NAN,
            ..options
        },
    ] {
        let (s, out) = register(&model, &source, &bad, &mut scratch);
        assert_eq!(s, PCRNET_ERROR_INVALID_OPTION, "{bad:?}");
        assert_eq!(out, sentinel());
    }
}

#[test]
fn every_status_has_a_message_naming_what_to_do() {
    use PcrnetStatus::*;
    let all = [
        PCRNET_OK,
        PCRNET_ERROR_NULL_POINTER,
        PCRNET_ERROR_MISALIGNED,
        PCRNET_ERROR_NOT_LOADED,
        PCRNET_ERROR_BAD_MAGIC,
        PCRNET_ERROR_UNSUPPORTED_VERSION,
        PCRNET_ERROR_WRONG_KIND,
        PCRNET_ERROR_TRUNCATED,
        PCRNET_ERROR_TRAILING_DATA,
        PCRNET_ERROR_BAD_CRC,
        PCRNET_ERROR_MALFORMED,
        PCRNET_ERROR_INCONSISTENT_DIMENSIONS,
        PCRNET_ERROR_INVALID_PARAMETER,
        PCRNET_ERROR_SCRATCH_TOO_SMALL,
        PCRNET_ERROR_BUFFER_TOO_SMALL,
        PCRNET_ERROR_EMPTY_CLOUD,
        PCRNET_ERROR_NON_FINITE_COORDINATE,
        PCRNET_ERROR_NO_POINT_IN_RANGE,
        PCRNET_ERROR_DEGENERATE_POSE,
        PCRNET_ERROR_NON_FINITE_RESULT,
        PCRNET_ERROR_INVALID_OPTION,
        PCRNET_ERROR_INVALID_POSE,
        PCRNET_ERROR_INVALID_FRAME,
        PCRNET_ERROR_NO_HEAD,
        PCRNET_ERROR_NO_LK_SOLVER,
        PCRNET_ERROR_OTHER,
    ];
    let message = |s: i32| unsafe { CStr::from_ptr(pcrnet_status_message(s)) }.to_str();
    let unknown = message(12345).unwrap();
    assert_eq!(unknown, "unknown status");
    let mut seen = std::collections::HashSet::new();
    for s in all {
        let text = message(s as i32).unwrap();
        assert_ne!(text, unknown, "{s:?} has no message");
        assert!(seen.insert(text), "{s:?} shares its message");
    }
}

/// A prepared handle (`pcrnet_prepare`) registers and runs the network
/// exactly as the plain calls do, on the host scratch and on the smallest
/// one; a handle never prepared, or whose preparation failed, is a status
/// and nothing is written.
#[test]
fn prepared_calls_are_bit_identical_to_the_plain_ones() {
    use PcrnetStatus::*;
    let blob = shipped_blob();
    let model = loaded(&blob);
    let source = shipped_source();
    let points = source.as_ptr() as *const f32;
    let host_len = unsafe { pcrnet_model_host_scratch_len(&*model) };
    let small_len = unsafe { pcrnet_model_scratch_len(&*model, 1) };
    let mut plain = vec![0i8; host_len];
    for len in [host_len, small_len] {
        let mut scratch = vec![0i8; len];
        let mut prepared = PcrnetPrepared::new();
        let status =
            unsafe { pcrnet_prepare(&*model, scratch.as_mut_ptr(), scratch.len(), &mut prepared) };
        assert_eq!(status, PCRNET_OK);
        for options in [Options::default(), Options::network_only()] {
            let c_options = PcrnetOptions::from(options);
            let mut got = sentinel();
            let status = unsafe {
                pcrnet_prepared_register(&mut prepared, points, source.len(), &c_options, &mut got)
            };
            assert_eq!(status, PCRNET_OK);
            let (status, want) = register(&model, &source, &c_options, &mut plain);
            assert_eq!(status, PCRNET_OK);
            assert_eq!(got, want, "scratch {len}");
        }
        let (mut pose, mut passes) = ([0f32; 7], 0u32);
        let status = unsafe {
            pcrnet_prepared_network_pose(
                &mut prepared,
                points,
                source.len(),
                3,
                0.0,
                pose.as_mut_ptr(),
                &mut passes,
            )
        };
        assert_eq!(status, PCRNET_OK);
        let rust = Int8Model::from_bytes(&blob).unwrap();
        let (p, n) = rust.network_pose(&source, 3, 0.0, &mut plain).unwrap();
        assert_eq!(
            (passes as usize, pose[..4].to_vec(), pose[4..].to_vec()),
            (n, p.rotation.to_vec(), p.translation.to_vec())
        );
    }
    // Never prepared; prepared on a scratch one byte short (refused, and
    // marked not prepared); null handles.
    let options = options_default();
    let mut blank = PcrnetPrepared::new();
    let mut out = sentinel();
    let call = |p: *mut PcrnetPrepared, out: &mut PcrnetRegistration| unsafe {
        pcrnet_prepared_register(p, points, source.len(), &options, out)
    };
    assert_eq!(call(&mut blank, &mut out), PCRNET_ERROR_NOT_PREPARED);
    let mut short = vec![0i8; small_len - 1];
    let mut failed = PcrnetPrepared::new();
    let mut scratch = vec![0i8; small_len];
    let status =
        unsafe { pcrnet_prepare(&*model, scratch.as_mut_ptr(), scratch.len(), &mut failed) };
    assert_eq!(status, PCRNET_OK);
    let status = unsafe { pcrnet_prepare(&*model, short.as_mut_ptr(), short.len(), &mut failed) };
    assert_eq!(status, PCRNET_ERROR_SCRATCH_TOO_SMALL);
    assert_eq!(call(&mut failed, &mut out), PCRNET_ERROR_NOT_PREPARED);
    assert_eq!(
        call(std::ptr::null_mut(), &mut out),
        PCRNET_ERROR_NULL_POINTER
    );
    let unloaded = zeroed_model();
    let status =
        unsafe { pcrnet_prepare(&*unloaded, scratch.as_mut_ptr(), scratch.len(), &mut failed) };
    assert_eq!(status, PCRNET_ERROR_NOT_LOADED);
    let status = unsafe {
        pcrnet_prepare(
            &*model,
            scratch.as_mut_ptr(),
            scratch.len(),
            std::ptr::null_mut(),
        )
    };
    assert_eq!(status, PCRNET_ERROR_NULL_POINTER);
    assert_eq!(out, sentinel(), "a failed call wrote its output");
    let message =
        unsafe { CStr::from_ptr(pcrnet_status_message(PCRNET_ERROR_NOT_PREPARED as i32)) };
    assert!(
        message.to_str().unwrap().contains("pcrnet_prepare"),
        "{message:?}"
    );
}

/// A blob carrying the template's residual floor (format 6): the C API
/// reads it, and the options for the model carry the calibrated verdict;
/// the shipped blob (format 4) and a null handle have none.
#[test]
fn the_residual_floor_reaches_the_options_for_the_model() {
    use pcrnet_core::format::{self, ModelKind, Trailer};
    let shipped = shipped_blob();
    let rust = Int8Model::from_bytes(&shipped).unwrap();
    let trailer = Trailer {
        table: rust.template().table(),
        residual_floor: Some(0.02),
        ..Trailer::default()
    };
    let mut blob = vec![0u8; format::blob_len(rust.payload(), &trailer).unwrap()];
    format::write_blob(ModelKind::Int8, rust.payload(), &trailer, &mut blob).unwrap();
    let model = loaded(&blob);
    assert_eq!(unsafe { pcrnet_model_residual_floor(&*model) }, 0.02);
    let mut for_model = options_default();
    let status = unsafe { pcrnet_options_for_model(&*model, &mut for_model) };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert_eq!(
        for_model.max_residual,
        0.02 + pcrnet_core::registration::NOISE_ALLOWANCE
    );
    let plain = loaded(&shipped);
    assert_eq!(unsafe { pcrnet_model_residual_floor(&*plain) }, -1.0);
    let status = unsafe { pcrnet_options_for_model(&*plain, &mut for_model) };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert_eq!(for_model.max_residual, Options::default().max_residual);
    assert_eq!(
        unsafe { pcrnet_model_residual_floor(std::ptr::null()) },
        -1.0
    );
}
