//! The feature-space check on the shipped model: a source moved onto the
//! template by its true pose is near the template's feature, one moved by
//! a wrong pose is not, and bad input is an error, not a number.

mod common;

use common::{angle_deg, rotation, template};
use pcrnet_core::pose::Pose;
use pcrnet_core::testing::SplitMix64;
use pcrnet_core::{Error, Int8Model};

const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");

#[test]
fn the_true_pose_is_near_the_template_feature_a_wrong_one_is_not() {
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let mut scratch = vec![0i8; model.scratch_len(8)];
    let t = template();
    let mut rng = SplitMix64(31);
    let (mut right, mut wrong) = (Vec::new(), Vec::new());
    for _ in 0..12 {
        let axis = [0; 3].map(|_: i32| rng.uniform(-1.0, 1.0));
        let truth = Pose {
            translation: [0; 3].map(|_: i32| rng.uniform(-0.5, 0.5)),
            ..rotation(axis, rng.uniform(10.0, 170.0))
        };
        // The template's points seen from the source's frame, with noise.
        let back = truth.inverse();
        let source: Vec<[f32; 3]> = t
            .iter()
            .map(|&p| {
                back.transform_point(p)
                    .map(|v| v + rng.uniform(-0.005, 0.005))
            })
            .collect();
        right.push(
            model
                .feature_distance(&source, &truth, &mut scratch)
                .unwrap(),
        );
        let off = rotation([axis[1], -axis[0], 0.5], 40.0).then(&truth);
        assert!((angle_deg(&off, &truth) - 40.0).abs() < 0.1);
        wrong.push(model.feature_distance(&source, &off, &mut scratch).unwrap());
    }
    let worst_right = right.iter().cloned().fold(0.0, f32::max);
    let best_wrong = wrong.iter().cloned().fold(f32::INFINITY, f32::min);
    assert!(worst_right < best_wrong, "{worst_right} vs {best_wrong}");
    // The same call twice gives the same bits.
    let again = model
        .feature_distance(&t, &Pose::IDENTITY, &mut scratch)
        .unwrap();
    assert_eq!(
        again.to_bits(),
        model
            .feature_distance(&t, &Pose::IDENTITY, &mut scratch)
            .unwrap()
            .to_bits()
    );
    assert!(again < worst_right.max(0.05), "{again}");
}

#[test]
fn bad_input_is_an_error() {
    let model = Int8Model::from_bytes(MODEL).unwrap();
    let mut scratch = vec![0i8; model.scratch_len(1)];
    let nan_pose = Pose {
        translation: [f32::NAN, 0.0, 0.0],
        ..Pose::IDENTITY
    };
    let t = template();
    assert_eq!(
        model.feature_distance(&t, &nan_pose, &mut scratch),
        Err(Error::NonFiniteResult)
    );
    assert_eq!(
        model.feature_distance(&[], &Pose::IDENTITY, &mut scratch),
        Err(Error::EmptyCloud)
    );
    let mut bad = t.clone();
    bad[3][1] = f32::INFINITY;
    assert_eq!(
        model.feature_distance(&bad, &Pose::IDENTITY, &mut scratch),
        Err(Error::NonFiniteCoordinate { index: 3 })
    );
    assert!(matches!(
        model.feature_distance(&t, &Pose::IDENTITY, &mut []),
        Err(Error::ScratchTooSmall { .. })
    ));
}
