//! The block kernels' shared test helpers and the whole-encoder test.

use super::super::test_layer::{BlockCase, TestLayer};
use super::super::{Sink, dense_tile};
use super::*;
use crate::testing::SplitMix64;
use std::vec::Vec;

/// A block's inputs (`BLOCK` rows of `inputs`) as int16 pairs by point.
pub(super) fn pairs_by_point(x: &[i8], inputs: usize) -> Vec<u32> {
    let count = inputs.div_ceil(2);
    let mut words = std::vec![0u32; count * BLOCK];
    for (p, row) in x.chunks(inputs).enumerate() {
        for j in 0..count {
            let v = |k: usize| row.get(k).map_or(0, |&v| v as i16);
            words[j * BLOCK + p] = pair(v(2 * j), v(2 * j + 1));
        }
    }
    words
}

/// A block's inputs as byte quads by point, each byte XOR `flip`
/// (0x80: `x + 128`, as the VNNI route holds them; 0: signed, as the
/// SDOT route does), `pad` in the bytes past `inputs`.
pub(super) fn quads_by_point(x: &[i8], inputs: usize, pad: u8, flip: u8) -> Vec<u32> {
    let count = inputs.div_ceil(4);
    let mut quads = std::vec![0u32; count * BLOCK];
    for (p, row) in x.chunks(inputs).enumerate() {
        for j in 0..count {
            let byte = |k: usize| row.get(k).map_or(pad, |&v| v as u8 ^ flip);
            quads[j * BLOCK + p] = u32::from_le_bytes([0, 1, 2, 3].map(|k| byte(4 * j + k)));
        }
    }
    quads
}

/// The activations a block's [`Out::Quads`] holds (bytes XOR `flip`),
/// `BLOCK` rows of `outputs`; checks that the bytes past the last
/// output read activation 0.
fn from_quads(quads: &[u32], outputs: usize, flip: u8) -> Vec<i8> {
    let byte =
        |o: usize, p: usize| ((quads[o / 4 * BLOCK + p] >> (8 * (o % 4))) as u8 ^ flip) as i8;
    for o in outputs..outputs.next_multiple_of(4) {
        for p in 0..BLOCK {
            assert_eq!(byte(o, p), 0, "a missing output's byte");
        }
    }
    (0..BLOCK * outputs)
        .map(|i| byte(i % outputs, i / outputs))
        .collect()
}

/// A quad route's layer kernel (`run`, into the [`Out`] it is given),
/// its activations stored as quads (bytes XOR `flip`) and max-pooled,
/// against the portable kernel's on case `c`.
pub(super) fn check_layer(c: &BlockCase, kernel: &str, flip: u8, run: &dyn Fn(Out<'_>)) {
    let (q, outputs) = (c.layer.requant(), c.outputs);
    let what = std::format!("{kernel}, {}, {} -> {outputs}", c.what, c.inputs);
    let mut want = std::vec![0i8; BLOCK * outputs];
    let sink = &mut Sink::Store {
        out: &mut want,
        outputs,
    };
    dense_tile(&c.layer.weights, c.inputs, q, &c.x, sink);
    let mut got = std::vec![0x5A5A_5A5Au32; outputs.div_ceil(4) * BLOCK];
    run(Out::Quads(&mut got));
    assert_eq!(from_quads(&got, outputs, flip), want, "{what}, stored");
    let (mut want, mut got) = (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
    dense_tile(
        &c.layer.weights,
        c.inputs,
        q,
        &c.x,
        &mut Sink::Pool(&mut want),
    );
    let mut maxima = std::vec![i32::MIN as u32; outputs];
    run(Out::Maxima(&mut maxima));
    pool_maxima(&maxima, q, &mut got);
    assert_eq!(got, want, "{what}, pooled");
}

/// Every route this CPU can run (the tests say which they cannot).
fn routes() -> Vec<Route> {
    #[cfg(target_arch = "x86_64")]
    {
        let mut routes = Vec::new();
        if std::is_x86_feature_detected!("avx2") {
            routes.push(Route::Avx2);
        }
        if vnni::has_vnni() {
            routes.push(Route::Vnni);
        } else {
            std::eprintln!("no AVX-512 VNNI on this CPU: its route not tested");
        }
        if avxvnni::has_avxvnni() {
            routes.push(Route::AvxVnni);
        } else {
            std::eprintln!("no AVX-VNNI on this CPU: its route not tested");
        }
        routes
    }
    #[cfg(target_arch = "aarch64")]
    {
        if sdot::has_sdot() {
            std::vec![Route::Sdot]
        } else {
            std::eprintln!("no dot-product extension on this CPU: the SDOT route not tested");
            Vec::new()
        }
    }
}

/// The whole block encoder, on every route the CPU can run, gives the
/// pooled feature of the portable kernels over two blocks: encoders of
/// one layer, of odd widths and of the embedded widths, both
/// requantization paths.
#[test]
fn block_encoder_matches_portable_on_every_route() {
    let routes = routes();
    let mut rng = SplitMix64(40);
    let encoders: [&[u16]; 4] = [&[8], &[7, 33, 65], &[32, 64, 128, 256], &[16, 16]];
    for widths in encoders {
        for shifts in [(-22, -2), (-31, 31)] {
            let arch = Arch::new(widths, &[]).unwrap();
            let shapes: Vec<_> = arch.encoder_layers().collect();
            let random: Vec<TestLayer> = shapes
                .iter()
                .map(|s| TestLayer::new(&mut rng, s.inputs, s.outputs, shifts))
                .collect();
            let layers: Vec<Int8Layer<'_>> = random
                .iter()
                .map(|l| Int8Layer {
                    out_scale: 1.0,
                    out_zero_point: l.zero_point,
                    weights: &l.weights,
                    bias: &l.bias,
                    multiplier: &l.multiplier,
                    shift: &l.shift,
                })
                .collect();
            let blocks: Vec<[[i16; INPUT_DIM]; BLOCK]> = (0..2)
                .map(|_| core::array::from_fn(|_| [0; 3].map(|_| rng.int(-2000, 2000) as i16)))
                .collect();
            // The portable kernels, point by point.
            let mut want = std::vec![i8::MIN; *widths.last().unwrap() as usize];
            for points in &blocks {
                let (first, q) = (&random[0], random[0].requant());
                let mut x: Vec<i8> = points
                    .iter()
                    .flat_map(|p| {
                        let rows = super::super::rows(&first.weights, 3);
                        let params = le_i32s(q.bias).zip(le_i32s(q.multiplier)).zip(q.shift);
                        rows.zip(params).map(move |(w, ((b, m), &s))| {
                            let dot = w
                                .iter()
                                .zip(p)
                                .fold(b, |a, (&w, &c)| a.wrapping_add(w as i8 as i32 * c as i32));
                            OutputStep::new(m, s as i8, q.zero_point, q.act_min).apply(dot)
                        })
                    })
                    .collect();
                for (l, shape) in random.iter().zip(&shapes).skip(1) {
                    let mut out = std::vec![0i8; BLOCK * shape.outputs];
                    let sink = &mut Sink::Store {
                        out: &mut out,
                        outputs: shape.outputs,
                    };
                    dense_tile(&l.weights, shape.inputs, l.requant(), &x, sink);
                    x = out;
                }
                let last = shapes.last().unwrap().outputs;
                for acts in x.chunks(last) {
                    for (f, &v) in want.iter_mut().zip(acts) {
                        *f = (*f).max(v);
                    }
                }
            }
            for &route in &routes {
                let mut area = std::vec![0i8; arch.host_block_len()];
                let mut encoder =
                    BlockEncoder::with_route(&arch, &layers, &mut area, route).unwrap();
                let mut got = std::vec![i8::MIN; want.len()];
                for points in &blocks {
                    let steps = shapes
                        .iter()
                        .zip(&random)
                        .map(|(s, l)| (s.inputs, s.outputs, &l.weights[..], l.requant()));
                    encoder.encode(points, steps);
                }
                encoder.pool(random.last().unwrap().requant(), &mut got);
                assert_eq!(got, want, "{widths:?}, {shifts:?}, {route:?}");
            }
        }
    }
}
