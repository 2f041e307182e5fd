//! The int8 path against a plain reference, and its invariances.

use pcrnet_core::fixed::{quantize_coordinate, requantize};
use pcrnet_core::format::Int8Layer;
use pcrnet_core::testing::{SplitMix64, random_int8_blob_into};
use pcrnet_core::{Error, Int8Model, MAX_TILE, POSE_DIM};

const SMALL_ENC: &[u16] = &[16, 24, 64];
const SMALL_HEAD: &[u16] = &[48, 32];

fn blob(seed: u64, enc: &[u16], head: &[u16]) -> Vec<u8> {
    let mut arena = vec![0u8; 8 << 20];
    let mut out = vec![0u8; 8 << 20];
    random_int8_blob_into(seed, enc, head, &mut arena, &mut out)
        .unwrap()
        .to_vec()
}

fn cloud(seed: u64, n: usize, extent: f32) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| [0; 3].map(|_: i32| rng.uniform(-extent, extent)))
        .collect()
}

/// Straightforward i64 evaluation of one layer, written from the format's
/// documentation, independent of the crate's kernels.
fn ref_layer(l: &Int8Layer<'_>, x: &[i64], relu: bool) -> Vec<i64> {
    let inputs = x.len();
    let outputs = l.shift.len();
    (0..outputs)
        .map(|o| {
            let b = i32::from_le_bytes(l.bias[4 * o..4 * o + 4].try_into().unwrap()) as i64;
            let m = i32::from_le_bytes(l.multiplier[4 * o..4 * o + 4].try_into().unwrap());
            let acc: i64 = b
                + (0..inputs)
                    .map(|i| l.weights[o * inputs + i] as i8 as i64 * x[i])
                    .sum::<i64>();
            assert!(acc >= i32::MIN as i64 && acc <= i32::MAX as i64);
            let r = 31 - l.shift[o] as i8 as i64;
            let scaled = ((acc as i128 * m as i128 * 2 + (1i128 << r)) >> (r + 1)) as i64;
            let lo = if relu { l.out_zero_point as i64 } else { -128 };
            (scaled + l.out_zero_point as i64).clamp(lo, 127)
        })
        .collect()
}

fn reference(model: &Int8Model<'_>, points: &[[f32; 3]]) -> (Vec<i8>, [i32; POSE_DIM]) {
    let p = model.payload();
    let f = model.arch().feature_dim();
    let mut feature = vec![i64::MIN; f];
    for pt in points {
        let mut x: Vec<i64> = pt
            .iter()
            .map(|&c| quantize_coordinate(c, p.input_scale).unwrap() as i64)
            .collect();
        for l in &p.encoder {
            x = ref_layer(l, &x, true);
        }
        for (m, v) in feature.iter_mut().zip(x) {
            *m = (*m).max(v);
        }
    }
    let mut x: Vec<i64> = p
        .template_feature
        .iter()
        .map(|&b| b as i8 as i64)
        .chain(feature.iter().copied())
        .collect();
    for l in &p.head {
        x = ref_layer(l, &x, true);
    }
    let mut raw = [0i32; POSE_DIM];
    for (o, r) in raw.iter_mut().enumerate() {
        let b = i32::from_le_bytes(p.output.bias[4 * o..4 * o + 4].try_into().unwrap()) as i64;
        let acc = b
            + (0..x.len())
                .map(|i| p.output.weights[o * x.len() + i] as i8 as i64 * x[i])
                .sum::<i64>();
        *r = i32::try_from(acc).unwrap();
    }
    (feature.iter().map(|&v| v as i8).collect(), raw)
}

#[test]
fn matches_plain_reference_for_many_sizes() {
    // requantize is re-derived in ref_layer; check the two agree on a corner first.
    assert_eq!(requantize(-3, 1 << 30, 0), -1);
    for (seed, enc, head) in [
        (1u64, SMALL_ENC, SMALL_HEAD),
        (2, &[8][..], &[][..]),
        (3, &[32, 32, 128, 256][..], &[64][..]),
        (4, &[7, 33, 65][..], &[16][..]),
    ] {
        let b = blob(seed, enc, head);
        let model = Int8Model::from_bytes(&b).unwrap();
        // A full tile's scratch, and the host's (with the x86-64 block
        // kernel, where the CPU has AVX2).
        let mut tiles = vec![0i8; model.scratch_len(MAX_TILE)];
        let mut host = vec![0i8; model.host_scratch_len()];
        for n in [1usize, 2, 7, 8, 9, 32, 33, 64, 95, 1000] {
            let pts = cloud(seed * 100 + n as u64, n, 1.5);
            let (feature, raw) = reference(&model, &pts);
            for scratch in [&mut tiles, &mut host] {
                let got = model.infer(&pts, scratch).unwrap();
                assert_eq!(got.feature, &feature[..], "feature, seed {seed}, n {n}");
                assert_eq!(got.head, raw, "head, seed {seed}, n {n}");
            }
            // The activations must not be degenerate for the test to mean anything.
            if n < 33 {
                continue;
            }
            let distinct = feature
                .iter()
                .collect::<std::collections::BTreeSet<_>>()
                .len();
            assert!(
                distinct > feature.len().min(8) / 2,
                "feature too uniform: seed {seed} n {n} {feature:?}"
            );
        }
    }
}

#[test]
fn permutation_invariant_bit_exact() {
    let b = blob(11, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    let mut pts = cloud(12, 257, 1.0);
    let mut s1 = vec![0i8; model.scratch_len(4)];
    let first = model.infer_tiled(&pts, 4, &mut s1).unwrap();
    let (f1, h1) = (first.feature.to_vec(), first.head);
    let mut rng = SplitMix64(13);
    for _ in 0..5 {
        for i in (1..pts.len()).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            pts.swap(i, j);
        }
        let mut s2 = vec![0i8; model.scratch_len(4)];
        let again = model.infer_tiled(&pts, 4, &mut s2).unwrap();
        assert_eq!(again.feature, &f1[..]);
        assert_eq!(again.head, h1);
    }
}

#[test]
fn tile_size_does_not_change_anything() {
    let b = blob(21, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    for n in [1usize, 5, 31, 100] {
        let pts = cloud(22 + n as u64, n, 1.0);
        let mut s = vec![0i8; model.scratch_len(1)];
        let base = model.infer_tiled(&pts, 1, &mut s).unwrap();
        let (f, h) = (base.feature.to_vec(), base.head);
        for tile in 2..=MAX_TILE {
            let mut s = vec![0i8; model.scratch_len(tile)];
            let r = model.infer_tiled(&pts, tile, &mut s).unwrap();
            assert_eq!(r.feature, &f[..], "tile {tile}, n {n}");
            assert_eq!(r.head, h, "tile {tile}, n {n}");
        }
    }
}

#[test]
fn register_gives_a_unit_quaternion() {
    let b = blob(31, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    let mut s = vec![0i8; model.scratch_len(MAX_TILE)];
    let pose = model
        .network_pose(&cloud(32, 50, 1.0), 1, 0.0, &mut s)
        .map(|r| r.0)
        .unwrap();
    let n: f32 = pose.rotation.iter().map(|q| q * q).sum();
    assert!((n - 1.0).abs() < 1e-5);
    assert!(pose.rotation[0] >= 0.0);
}

#[test]
fn bad_clouds_are_typed_errors() {
    let b = blob(41, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    let mut s = vec![0i8; model.scratch_len(MAX_TILE)];
    assert_eq!(
        model.network_pose(&[], 1, 0.0, &mut s).map(|r| r.0),
        Err(Error::EmptyCloud)
    );
    let mut pts = cloud(42, 20, 1.0);
    pts[13][1] = f32::NAN;
    assert_eq!(
        model.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0),
        Err(Error::NonFiniteCoordinate { index: 13 })
    );
    pts[13][1] = f32::NEG_INFINITY;
    assert_eq!(
        model.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0),
        Err(Error::NonFiniteCoordinate { index: 13 })
    );
    // A point outside the input range (+-4) is left out of the network:
    // the same pose as without it, and counted.
    pts[13][1] = 4.5;
    let without: Vec<[f32; 3]> = [&pts[..13], &pts[14..]].concat();
    assert_eq!(
        model.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0),
        model.network_pose(&without, 1, 0.0, &mut s).map(|r| r.0),
    );
    assert_eq!(model.infer(&pts, &mut s).unwrap().out_of_range, 1);
    assert_eq!(model.infer(&without, &mut s).unwrap().out_of_range, 0);
    // Every point outside: no pose.
    let far = [[4.5, 0.0, 0.0], [0.0, -5.0, 0.0]];
    assert_eq!(
        model.network_pose(&far, 1, 0.0, &mut s).map(|r| r.0),
        Err(Error::NoPointInRange)
    );
    // Extreme but valid coordinates work.
    pts[13] = [3.9999, -3.9999, 0.0];
    assert!(
        model
            .network_pose(&pts, 1, 0.0, &mut s)
            .map(|r| r.0)
            .is_ok()
    );
}

#[test]
fn scratch_is_checked_at_load_and_at_run() {
    let b = blob(51, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    let need = model.scratch_len(1);
    let small = vec![0i8; need - 1];
    assert_eq!(
        Int8Model::load(&b, &small).err(),
        Some(Error::ScratchTooSmall {
            needed: need,
            available: need - 1
        })
    );
    let mut small = small;
    assert!(matches!(
        model
            .network_pose(&cloud(1, 3, 1.0), 1, 0.0, &mut small)
            .map(|r| r.0),
        Err(Error::ScratchTooSmall { .. })
    ));
    assert!(matches!(
        model.infer_tiled(&cloud(1, 3, 1.0), 0, &mut small),
        Err(Error::InvalidParameter { .. })
    ));
    let exact = vec![0i8; need];
    assert!(Int8Model::load(&b, &exact).is_ok());
}

#[test]
fn paper_architecture_runs() {
    let b = blob(
        61,
        pcrnet_core::arch::PAPER_ENCODER,
        pcrnet_core::arch::PCRNET_HEAD,
    );
    let model = Int8Model::from_bytes(&b).unwrap();
    // Feature, then the head's area (see `int8_scratch_len`).
    assert_eq!(model.scratch_len(8), 1024 + 2 * 1024 + (2 * 2048 + 3));
    let mut s = vec![0i8; model.scratch_len(MAX_TILE)];
    let pts = cloud(62, 40, 1.0);
    let got = model.infer(&pts, &mut s).unwrap();
    let (feature, raw) = reference(&model, &pts);
    assert_eq!(got.feature, &feature[..]);
    assert_eq!(got.head, raw);
}

#[test]
fn iterative_registration_is_repeated_single_passes() {
    use pcrnet_core::pose::{Pose, Rigid};
    let b = blob(71, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    let mut s = vec![0i8; model.scratch_len(MAX_TILE)];
    let pts = cloud(72, 300, 0.8);
    // One pass is `register`, bit for bit.
    let single = model
        .network_pose(&pts, 1, 0.0, &mut s)
        .map(|r| r.0)
        .unwrap();
    assert_eq!(
        model.network_pose(&pts, 1, 0.0, &mut s).unwrap(),
        (single, 1)
    );
    // Three passes equal moving the cloud explicitly and composing by hand.
    let mut current = Pose::IDENTITY;
    for _ in 0..3 {
        let rigid = Rigid::from(&current);
        let moved: Vec<[f32; 3]> = pts.iter().map(|&p| rigid.apply(p)).collect();
        current = current.then(
            &model
                .network_pose(&moved, 1, 0.0, &mut s)
                .map(|r| r.0)
                .unwrap(),
        );
    }
    assert_eq!(
        model.network_pose(&pts, 3, 0.0, &mut s).unwrap(),
        (current, 3)
    );
    // A huge tolerance stops after the first pass.
    assert_eq!(model.network_pose(&pts, 10, 1e9, &mut s).unwrap().1, 1);
}

#[test]
fn centring_models_see_the_centred_source() {
    use pcrnet_core::pose::{Rigid, centring};
    use pcrnet_core::testing::random_int8_blob_with;
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    let centred = random_int8_blob_with(
        81,
        SMALL_ENC,
        SMALL_HEAD,
        true,
        pcrnet_core::Frame::IDENTITY,
        &mut arena,
        &mut out,
    )
    .unwrap()
    .to_vec();
    let plain = blob(81, SMALL_ENC, SMALL_HEAD);
    let (mc, mp) = (
        Int8Model::from_bytes(&centred).unwrap(),
        Int8Model::from_bytes(&plain).unwrap(),
    );
    assert!(mc.centres_source() && !mp.centres_source());
    // No more points than the network's sample, so `network_pose` encodes
    // every one of them, as `infer` does.
    let pts: Vec<[f32; 3]> = cloud(82, pcrnet_core::registration::NETWORK_POINTS, 0.5)
        .iter()
        .map(|p| [p[0] + 1.0, p[1] - 0.7, p[2] + 0.3])
        .collect();
    let every_point = pcrnet_core::pose::Centring::Centroid {
        radius: f32::INFINITY,
    };
    let start = centring(&pts, every_point, &pcrnet_core::Frame::IDENTITY).unwrap();
    let moved: Vec<[f32; 3]> = pts.iter().map(|&p| Rigid::from(&start).apply(p)).collect();
    let mut s1 = vec![0i8; mc.scratch_len(MAX_TILE)];
    let mut s2 = vec![0i8; mp.scratch_len(MAX_TILE)];
    let a = mc.infer(&pts, &mut s1).unwrap();
    let b = mp.infer(&moved, &mut s2).unwrap();
    // Same weights (same seed): the centring model encodes the raw cloud as
    // the plain model encodes the centred cloud, bit for bit. (The template
    // features differ: each model encoded the random template its own way.)
    assert_eq!(a.feature, b.feature);
    assert_eq!(a.centring, start);
    let head = a.head;
    let pose = mc.network_pose(&pts, 1, 0.0, &mut s1).map(|r| r.0).unwrap();
    assert_eq!(pose, start.then(&mc.pose(&head).unwrap()));
    // The rotation does not depend on where the cloud is.
    let shifted: Vec<[f32; 3]> = pts.iter().map(|p| [p[0] - 1.5, p[1], p[2] + 2.0]).collect();
    let other = mc
        .network_pose(&shifted, 1, 0.0, &mut s1)
        .map(|r| r.0)
        .unwrap();
    for (x, y) in pose.rotation.iter().zip(other.rotation) {
        assert!((x - y).abs() < 1e-3, "{pose:?} vs {other:?}");
    }
}

#[test]
fn finite_clouds_never_give_non_finite_poses() {
    use pcrnet_core::testing::random_int8_blob_with;
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    let centred = random_int8_blob_with(
        83,
        SMALL_ENC,
        SMALL_HEAD,
        true,
        pcrnet_core::Frame::IDENTITY,
        &mut arena,
        &mut out,
    )
    .unwrap()
    .to_vec();
    let model = Int8Model::from_bytes(&centred).unwrap();
    let mut s = vec![0i8; model.scratch_len(MAX_TILE)];
    // Centred, these points are in range; composing the centroid back
    // overflows f32: an error, not an infinite translation.
    for c in [3e38f32, -3e38] {
        let pts = [[c, c, c], [c, c, c], [c, -c, c], [c, c, -c]];
        for result in [
            model.network_pose(&pts[..2], 1, 0.0, &mut s).map(|r| r.0),
            model
                .register(&pts[..2], &pcrnet_core::Options::default(), &mut s)
                .map(|r| r.pose),
            model.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0),
        ] {
            match result {
                Ok(p) => assert!(p.is_finite(), "{p:?}"),
                Err(e) => assert!(
                    matches!(e, Error::NonFiniteResult | Error::NoPointInRange),
                    "{e:?}"
                ),
            }
        }
    }
}

#[test]
fn the_robust_centroid_leaves_out_stray_points_only() {
    use pcrnet_core::pose::{centroid, robust_centroid};
    let mut rng = SplitMix64(5);
    let cloud: Vec<[f32; 3]> = (0..500)
        .map(|_| [0; 3].map(|_: i32| rng.uniform(-0.5, 0.5)))
        .collect();
    // Every point within the radius: exactly the centroid, bit for bit.
    assert_eq!(robust_centroid(&cloud, 4.0), centroid(&cloud));
    // Two far points: the centroid of the others.
    let mut stray = cloud.clone();
    stray.insert(17, [1e9, 0.0, 0.0]);
    stray.push([0.0, -400.0, 3.0]);
    assert_eq!(robust_centroid(&stray, 4.0), centroid(&cloud));
    assert_ne!(centroid(&stray), centroid(&cloud));
    assert_eq!(
        robust_centroid(&[[0.0; 3], [0.0, f32::INFINITY, 0.0]], 4.0),
        Err(Error::NonFiniteCoordinate { index: 1 })
    );
    assert_eq!(robust_centroid(&[], 4.0), Err(Error::EmptyCloud));
}

/// The shipped trained model, whose pooled layer's inputs sit mostly in the
/// lower half of their range, so that the x86-64 host kernel runs the
/// pooled layer on bytes (the random models above make it decline): the
/// host scratch gives the tiles' bits (the tile kernels are checked against
/// the plain reference above; this model's frame moves the points first,
/// which `reference` does not do).
#[test]
fn trained_model_host_kernel_matches_tiles() {
    let blob = include_bytes!("../../models/embedded-default-int8.pcrn");
    let model = Int8Model::from_bytes(blob).unwrap();
    let mut tiles = vec![0i8; model.scratch_len(MAX_TILE)];
    let mut host = vec![0i8; model.host_scratch_len()];
    for (seed, n) in [(31u64, 48usize), (32, 1000), (33, 2048)] {
        let pts = cloud(seed, n, 0.5);
        let want = model.infer(&pts, &mut tiles).unwrap();
        let (feature, head) = (want.feature.to_vec(), want.head);
        let got = model.infer(&pts, &mut host).unwrap();
        assert_eq!(got.feature, &feature[..], "feature, n {n}");
        assert_eq!(got.head, head, "head, n {n}");
    }
}

/// The network's sample (`Options::network_points`): every k-th point,
/// checked for NaN over the whole cloud all the same, and a sample that
/// covers the cloud registers it exactly as before sampling existed.
#[test]
fn the_network_encodes_a_sample_and_every_point_is_checked() {
    use pcrnet_core::Options;
    let b = blob(43, SMALL_ENC, SMALL_HEAD);
    let model = Int8Model::from_bytes(&b).unwrap();
    let mut s = vec![0i8; model.scratch_len(MAX_TILE)];
    let pts = cloud(44, 600, 1.0);
    let options = Options {
        network_points: 256,
        ..Options::default()
    };
    // ceil(600 / 256) = 3: points 0, 3, ..., 597.
    let sample: Vec<[f32; 3]> = options.network_sample(&pts).copied().collect();
    assert_eq!(sample.len(), 200);
    assert_eq!(sample[0], pts[0]);
    assert_eq!(sample[199], pts[597]);
    // Point 1 is not sampled; its NaN is an error all the same.
    let mut bad = pts.clone();
    bad[1][2] = f32::NAN;
    assert_eq!(
        model.register(&bad, &options, &mut s).map(|r| r.pose),
        Err(Error::NonFiniteCoordinate { index: 1 })
    );
    assert_eq!(
        model.network_pose(&bad, 1, 0.0, &mut s).map(|r| r.0),
        Err(Error::NonFiniteCoordinate { index: 1 })
    );
    // The network sees the sampled points only: the same pose whether the
    // others are there or not (this random model does not centre its
    // sources; one that does takes the centroid of the whole cloud), with
    // scoring on the same 200 points.
    let network_only = Options {
        network_points: 256,
        ..Options::network_only()
    };
    let alone = model.register(&sample, &network_only, &mut s).unwrap();
    let among = model
        .register(
            &pts,
            &Options {
                max_points: 200,
                ..network_only
            },
            &mut s,
        )
        .unwrap();
    assert_eq!(alone.pose, among.pose);
    // A sample as large as the cloud is the whole cloud.
    let all = Options {
        network_points: pts.len(),
        ..Options::network_only()
    };
    let more = Options {
        network_points: usize::MAX,
        ..all
    };
    assert_eq!(
        model.register(&pts, &all, &mut s).unwrap(),
        model.register(&pts, &more, &mut s).unwrap()
    );
}
