//! The f32 reference path.

use pcrnet_core::float::{Layer, dense};
use pcrnet_core::testing::{SplitMix64, random_f32_blob_into};
use pcrnet_core::{Error, F32Model};

fn blob(seed: u64) -> Vec<u8> {
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    random_f32_blob_into(seed, &[16, 32, 64], &[32, 16], &mut arena, &mut out)
        .unwrap()
        .to_vec()
}

fn cloud(seed: u64, n: usize) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| [0; 3].map(|_: i32| rng.uniform(-1.0, 1.0)))
        .collect()
}

#[test]
fn dense_matches_hand_computation() {
    let w = [1.0f32, 2.0, -1.0, 0.5];
    let b = [0.25f32, -10.0];
    let layer = Layer {
        weights: &w[..],
        bias: &b[..],
    };
    let mut out = [0f32; 2];
    dense(&layer, &[3.0, 4.0], 2, false, |o, v| out[o] = v);
    assert_eq!(out, [0.25 + 3.0 + 8.0, -10.0 - 3.0 + 2.0]);
    dense(&layer, &[3.0, 4.0], 2, true, |o, v| out[o] = v);
    assert_eq!(out, [11.25, 0.0]);
}

#[test]
fn permutation_invariant_and_deterministic() {
    let b = blob(3);
    let m = F32Model::from_bytes(&b).unwrap();
    let mut s = vec![0f32; m.scratch_len()];
    let mut pts = cloud(4, 100);
    let net = m.network();
    let f1 = net.encode(&pts, &mut s).unwrap().to_vec();
    let raw1 = net.infer(&pts, &mut s).unwrap();
    pts.reverse();
    pts.swap(3, 50);
    assert_eq!(net.encode(&pts, &mut s).unwrap(), &f1[..]);
    assert_eq!(net.infer(&pts, &mut s).unwrap(), raw1);
    let pose = m.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0).unwrap();
    let n: f32 = pose.rotation.iter().map(|q| q * q).sum();
    assert!((n - 1.0).abs() < 1e-5);
}

#[test]
fn bad_input_is_a_typed_error() {
    let b = blob(5);
    let m = F32Model::from_bytes(&b).unwrap();
    let mut s = vec![0f32; m.scratch_len()];
    assert_eq!(
        m.network_pose(&[], 1, 0.0, &mut s).map(|r| r.0),
        Err(Error::EmptyCloud)
    );
    assert_eq!(
        m.network_pose(&[[0.0, f32::NAN, 0.0]], 1, 0.0, &mut s)
            .map(|r| r.0),
        Err(Error::NonFiniteCoordinate { index: 0 })
    );
    let mut small = vec![0f32; m.scratch_len() - 1];
    assert!(matches!(
        m.register(&[[0.0; 3]], &pcrnet_core::Options::default(), &mut small),
        Err(Error::ScratchTooSmall { .. })
    ));
}

#[test]
fn iterative_registration_is_repeated_single_passes() {
    use pcrnet_core::pose::{Pose, Rigid};
    let b = blob(8);
    let m = F32Model::from_bytes(&b).unwrap();
    let mut s = vec![0f32; m.scratch_len()];
    let pts = cloud(9, 64);
    let mut current = Pose::IDENTITY;
    for _ in 0..2 {
        let rigid = Rigid::from(&current);
        let moved: Vec<[f32; 3]> = pts.iter().map(|&p| rigid.apply(p)).collect();
        current = current.then(&m.network_pose(&moved, 1, 0.0, &mut s).map(|r| r.0).unwrap());
    }
    assert_eq!(m.network_pose(&pts, 2, 0.0, &mut s).unwrap(), (current, 2));
}
