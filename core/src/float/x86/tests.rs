//! The f32 x86-64 kernels against the portable path and each other, bit
//! for bit.

use super::{F32_TILE, Layer, outputs, outputs_wide, pool_tile};
use crate::F32Model;
use crate::testing::{SplitMix64, random_f32_blob_into};
use std::vec::Vec;

/// The tile's max-pool keeps the bits of the point-by-point one: the
/// first of two zeros, no NaN, `f` unless a point is larger, lanes past
/// the tile's points (repeats of its first) never counted, over tiles
/// drawn from values that make each of these matter.
#[test]
fn tile_pool_matches_point_by_point() {
    if !std::is_x86_feature_detected!("avx") {
        return;
    }
    let values = [
        -0.0,
        0.0,
        1.0,
        -1.0,
        f32::NAN,
        2.5,
        f32::NEG_INFINITY,
        3e-39,
    ];
    let mut rng = SplitMix64(41);
    let (mut zeros, mut taken) = (0, 0);
    for _ in 0..20_000 {
        let n = rng.int(1, F32_TILE as i32) as usize;
        let mut v = [0f32; F32_TILE];
        for x in v.iter_mut().take(n) {
            *x = values[rng.int(0, values.len() as i32 - 1) as usize];
        }
        let first = v[0];
        v.iter_mut().skip(n).for_each(|x| *x = first);
        let start = [f32::NEG_INFINITY, -0.0, 0.0, -1.0, 1.0][rng.int(0, 4) as usize];
        let mut want = start;
        for &x in v.iter().take(n) {
            super::pool(&mut want, x);
        }
        let mut got = start;
        // SAFETY: the CPU has AVX (checked above).
        #[allow(unsafe_code)]
        unsafe {
            pool_tile(&mut got, &v, n)
        };
        assert_eq!(
            got.to_bits(),
            want.to_bits(),
            "{v:?} ({n} points) from {start}"
        );
        zeros += usize::from(want == 0.0 && want.to_bits() != start.to_bits());
        taken += usize::from(want.to_bits() != start.to_bits());
    }
    // Both branches ran: zeros that entered, and other values.
    assert!(
        zeros > 100 && taken > zeros + 100,
        "{zeros} zeros of {taken}"
    );
}

/// With room for tiles, the encoder and the head give the one-point
/// path's bits, for clouds shorter than, equal to and longer than a
/// tile, centred or not, with coordinates that drive sums below zero.
#[test]
fn tiled_encoder_matches_one_point_path() {
    if !std::is_x86_feature_detected!("avx") {
        return;
    }
    let (mut arena, mut out) = (std::vec![0u8; 1 << 20], std::vec![0u8; 1 << 20]);
    for (seed, encoder, head) in [(3, &[16, 24, 64][..], &[32][..]), (4, &[8][..], &[][..])] {
        let blob = random_f32_blob_into(seed, encoder, head, &mut arena, &mut out).unwrap();
        let model = F32Model::from_bytes(blob).unwrap();
        let mut rng = SplitMix64(seed);
        // 600: the network's sample (encode_moved) strides every third point.
        for n in [1, 15, 16, 17, 100, 600] {
            let cloud: Vec<[f32; 3]> = (0..n)
                .map(|_| [0; 3].map(|_: i32| rng.uniform(-2.0, 2.0)))
                .collect();
            for centre in [false, true] {
                let net = model.network().clone().with_centring(centre);
                let mut small = std::vec![0f32; net.scratch_len()];
                let mut tiled = std::vec![0f32; net.tiled_scratch_len()];
                // One layer needs no tile buffers: the kernel runs either way.
                assert!(tiled.len() > small.len() || encoder.len() == 1);
                let want = net.encode(&cloud, &mut small).unwrap().to_vec();
                let got = net.encode(&cloud, &mut tiled).unwrap().to_vec();
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "{n} points, centred {centre}");
                let want = net.infer(&cloud, &mut small).unwrap();
                let got = net.infer(&cloud, &mut tiled).unwrap();
                assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits));
                let moved = crate::Pose::IDENTITY;
                let want = net
                    .encode_moved(&cloud, &moved, &mut small)
                    .unwrap()
                    .to_vec();
                let got = net
                    .encode_moved(&cloud, &moved, &mut tiled)
                    .unwrap()
                    .to_vec();
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "{n} points sampled, centred {centre}"
                );
            }
        }
    }
}

/// The AVX-512 block kernel gives the AVX one's bits, eight outputs
/// against two passes of four, for widths around multiples of eight and
/// sixteen, sums on both sides of zero (the ReLU), and a NaN input.
#[test]
fn wide_block_matches_avx_block() {
    if !std::is_x86_feature_detected!("avx512f") {
        std::eprintln!("no AVX-512F on this CPU: outputs_wide not tested");
        return;
    }
    let mut rng = SplitMix64(10);
    for inputs in [1, 3, 7, 16, 33, 64, 130] {
        let w: Vec<f32> = (0..8 * inputs).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let mut x: Vec<f32> = (0..F32_TILE * inputs)
            .map(|_| rng.uniform(-2.0, 2.0))
            .collect();
        if inputs == 33 {
            x[5] = f32::NAN;
        }
        let bias: [f32; 8] = core::array::from_fn(|_| rng.uniform(-0.5, 0.5));
        let rows: [&[f32]; 8] = core::array::from_fn(|j| &w[j * inputs..(j + 1) * inputs]);
        // SAFETY: the CPU has AVX-512F (checked above), and so AVX.
        #[allow(unsafe_code)]
        let (wide, lo, hi) = unsafe {
            (
                outputs_wide(rows, bias, &x),
                outputs(
                    [rows[0], rows[1], rows[2], rows[3]],
                    [bias[0], bias[1], bias[2], bias[3]],
                    &x,
                ),
                outputs(
                    [rows[4], rows[5], rows[6], rows[7]],
                    [bias[4], bias[5], bias[6], bias[7]],
                    &x,
                ),
            )
        };
        let bits =
            |v: &[[f32; F32_TILE]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        let narrow: Vec<[f32; F32_TILE]> = lo.into_iter().chain(hi).collect();
        assert_eq!(bits(&wide), bits(&narrow), "{inputs} inputs");
        assert!(wide.iter().flatten().any(|&v| v == 0.0), "some ReLU clamps");
    }
}

/// Eight outputs a lane each give the one-output loop's bits (written
/// out here as the reference), over a concatenated input, with and
/// without ReLU, for widths around multiples of eight.
#[test]
fn rows_of_eight_match_one_output_loop() {
    let mut rng = SplitMix64(9);
    for (na, nx, outputs) in [(0, 3, 8), (8, 8, 17), (13, 5, 7), (64, 64, 64), (0, 1, 9)] {
        let inputs = na + nx;
        let w: Vec<f32> = (0..inputs * outputs)
            .map(|_| rng.uniform(-1.0, 1.0))
            .collect();
        let b: Vec<f32> = (0..outputs).map(|_| rng.uniform(-0.5, 0.5)).collect();
        let a: Vec<f32> = (0..na).map(|_| rng.uniform(-3.0, 3.0)).collect();
        let x: Vec<f32> = (0..nx).map(|_| rng.uniform(-3.0, 3.0)).collect();
        let layer = Layer {
            weights: &w[..],
            bias: &b[..],
        };
        for relu in [false, true] {
            let mut got = std::vec![f32::NAN; outputs];
            super::super::dense_concat(&layer, &a[..], &x, outputs, relu, |o, v| got[o] = v);
            let want: Vec<f32> = (0..outputs)
                .map(|o| {
                    let mut acc = b[o];
                    for (i, v) in a.iter().chain(&x).enumerate() {
                        acc += w[o * inputs + i] * v;
                    }
                    if relu && acc < 0.0 { 0.0 } else { acc }
                })
                .collect();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&got),
                bits(&want),
                "{na} + {nx} -> {outputs}, relu {relu}"
            );
        }
    }
}

/// The first non-finite coordinate is named as on the one-point path.
#[test]
fn names_the_non_finite_point() {
    let (mut arena, mut out) = (std::vec![0u8; 1 << 20], std::vec![0u8; 1 << 20]);
    let blob = random_f32_blob_into(5, &[16, 32], &[16], &mut arena, &mut out).unwrap();
    let model = F32Model::from_bytes(blob).unwrap();
    let mut cloud = std::vec![[0.1f32, 0.2, 0.3]; 40];
    cloud[21][1] = f32::NAN;
    let mut tiled = std::vec![0f32; model.tiled_scratch_len()];
    let err = model.network().encode(&cloud, &mut tiled).unwrap_err();
    assert_eq!(err, crate::Error::NonFiniteCoordinate { index: 21 });
}
