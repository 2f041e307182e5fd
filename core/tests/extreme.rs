//! Extreme finite coordinates through the f32 and int8 paths: every call
//! returns a typed error or a result whose every f32 is finite (issue 14:
//! four points at +-3e38 used to give a translation of -inf).

use pcrnet_core::format::{self, F32Payload, ModelKind};
use pcrnet_core::testing::{random_f32_blob_into, random_int8_blob_with};
use pcrnet_core::{Error, F32Model, Frame, Int8Model, Options, Registration};
use proptest::prelude::*;

/// Magnitudes from the largest finite f32 down to subnormals, both signs.
const EXTREMES: [f32; 12] = [
    f32::MAX,
    3e38,
    1e30,
    1e20,
    1e10,
    65_504.0,
    1.0,
    1e-10,
    1e-38,
    f32::MIN_POSITIVE,
    1e-45,
    0.0,
];

fn coordinate() -> impl Strategy<Value = f32> {
    (0..EXTREMES.len(), any::<bool>(), 0.0f32..1.0).prop_map(|(i, negative, jitter)| {
        let v = EXTREMES[i] * (1.0 - 1e-3 * jitter);
        if negative { -v } else { v }
    })
}

fn cloud() -> impl Strategy<Value = Vec<[f32; 3]>> {
    prop::collection::vec([coordinate(), coordinate(), coordinate()], 1..12)
}

/// Centimetres far from the origin: moving into the model frame multiplies.
const CM_FRAME: Frame = Frame {
    centre: [250.0, -40.0, 1000.0],
    scale: 0.01,
};

fn int8_blobs() -> Vec<Vec<u8>> {
    [
        (false, Frame::IDENTITY),
        (true, Frame::IDENTITY),
        (true, CM_FRAME),
    ]
    .iter()
    .enumerate()
    .map(|(i, &(centre, frame))| {
        let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
        random_int8_blob_with(
            40 + i as u64,
            &[16, 32],
            &[32],
            centre,
            frame,
            &mut arena,
            &mut out,
        )
        .unwrap()
        .to_vec()
    })
    .collect()
}

/// The random f32 model, and the same with centred sources.
fn f32_blobs() -> Vec<Vec<u8>> {
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    let plain = random_f32_blob_into(41, &[16, 32], &[32], &mut arena, &mut out)
        .unwrap()
        .to_vec();
    let mut payload: F32Payload<'_> = format::decode_model(&plain, ModelKind::F32).unwrap().0;
    payload.centre_source = true;
    let mut centred = vec![0u8; format::blob_len(&payload, &format::Trailer::default()).unwrap()];
    format::write_blob(
        ModelKind::F32,
        &payload,
        &format::Trailer::default(),
        &mut centred,
    )
    .unwrap();
    vec![plain.clone(), centred]
}

fn assert_finite(r: &Registration) {
    let fit = [
        r.residual,
        r.relative_residual,
        r.fitness,
        r.inlier_rmse,
        r.plane_residual,
        r.relative_plane_residual,
    ];
    let values = r
        .pose
        .rotation
        .iter()
        .chain(&r.pose.translation)
        .chain(&fit);
    for v in values {
        assert!(v.is_finite(), "{r:?}");
    }
}

/// Errors a hostile cloud may give; anything else is a bug.
fn expected_error(e: &Error) -> bool {
    matches!(
        e,
        Error::NoPointInRange | Error::NonFiniteResult | Error::DegeneratePose
    )
}

#[test]
fn four_points_at_3e38_are_an_error_not_infinity() {
    let spread = [
        [3e38, 3e38, 3e38],
        [-3e38, 3e38, -3e38],
        [3e38, -3e38, 3e38],
        [-3e38, -3e38, -3e38],
    ];
    // Identical points: centred, they sit at the origin, in range, and the
    // centring translation (3e38) comes back into the pose.
    let together = [[3e38, -3e38, 3e38]; 4];
    let out_of_range = Error::NoPointInRange;
    for source in [&spread, &together] {
        for blob in int8_blobs() {
            let m = Int8Model::from_bytes(&blob).unwrap();
            let mut s = vec![0i8; m.scratch_len(8)];
            let e = m.register(source, &Options::default(), &mut s).unwrap_err();
            // Out of the input range unless centring brought some in (the
            // robust centre sits on one of the spread points, and on all of
            // the points together); then the centre, 3e38, makes the pose
            // overflow.
            let want = if m.centres_source() {
                Error::NonFiniteResult
            } else {
                out_of_range
            };
            assert_eq!(e, want, "int8, centred {}", m.centres_source());
        }
        for blob in f32_blobs() {
            let m = F32Model::from_bytes(&blob).unwrap();
            let mut s = vec![0f32; m.scratch_len()];
            let e = m.register(source, &Options::default(), &mut s).unwrap_err();
            assert_eq!(
                e,
                Error::NonFiniteResult,
                "f32, centred {}",
                m.centres_source()
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn extreme_clouds_give_finite_results_or_errors(source in cloud()) {
        let options = Options { icp_iterations: 5, ..Options::default() };
        for blob in int8_blobs() {
            let m = Int8Model::from_bytes(&blob).unwrap();
            let mut s = vec![0i8; m.scratch_len(8)];
            match m.register(&source, &options, &mut s) {
                Ok(r) => assert_finite(&r),
                Err(e) => prop_assert!(expected_error(&e), "{:?}", e),
            }
            match m.network_pose(&source, 2, 0.0, &mut s) {
                Ok((p, _)) => prop_assert!(p.is_finite()),
                Err(e) => prop_assert!(expected_error(&e), "{:?}", e),
            }
        }
        for blob in f32_blobs() {
            let m = F32Model::from_bytes(&blob).unwrap();
            let mut s = vec![0f32; m.scratch_len()];
            match m.register(&source, &options, &mut s) {
                Ok(r) => assert_finite(&r),
                Err(e) => prop_assert!(expected_error(&e), "{:?}", e),
            }
            match m.network().encode(&source, &mut s) {
                Ok(f) => prop_assert!(f.iter().all(|v| v.is_finite())),
                Err(e) => prop_assert!(expected_error(&e), "{:?}", e),
            }
            match m.network().infer(&source, &mut s) {
                Ok(raw) => prop_assert!(raw.iter().all(|v| v.is_finite())),
                Err(e) => prop_assert!(expected_error(&e), "{:?}", e),
            }
        }
    }
}
