//! A random int8 layer for the kernels' bit-exactness tests.

use super::{Requant, Sink};
use crate::testing::SplitMix64;
use std::vec::Vec;

/// Random weights, biases and output steps of one layer.
#[derive(Clone)]
pub(crate) struct TestLayer {
    pub weights: Vec<u8>,
    pub bias: Vec<u8>,
    pub multiplier: Vec<u8>,
    pub shift: Vec<u8>,
    pub zero_point: i8,
}

/// A random int8 value.
pub(crate) fn byte(rng: &mut SplitMix64) -> i8 {
    rng.int(-128, 127) as i8
}

impl TestLayer {
    /// `outputs` rows of `inputs` random weights, biases up to 2^20,
    /// multipliers in [2^30, 2^31), shifts in `shifts` (inclusive; beyond
    /// -22..=-2 the output step takes its general path) and a random zero
    /// point.
    pub(crate) fn new(
        rng: &mut SplitMix64,
        inputs: usize,
        outputs: usize,
        shifts: (i32, i32),
    ) -> Self {
        let weights = (0..inputs * outputs).map(|_| byte(rng) as u8).collect();
        let mut words = |lo: i32, hi: i32| -> Vec<u8> {
            (0..outputs)
                .flat_map(|_| rng.int(lo, hi).to_le_bytes())
                .collect()
        };
        let bias = words(-1 << 20, 1 << 20);
        let multiplier = words(1 << 30, i32::MAX);
        let shift = (0..outputs)
            .map(|_| rng.int(shifts.0, shifts.1) as i8 as u8)
            .collect();
        TestLayer {
            weights,
            bias,
            multiplier,
            shift,
            zero_point: byte(rng),
        }
    }

    /// Its requantization, ReLU on (the zero point as the floor).
    pub(crate) fn requant(&self) -> Requant<'_> {
        Requant {
            bias: &self.bias,
            multiplier: &self.multiplier,
            shift: &self.shift,
            zero_point: self.zero_point,
            act_min: self.zero_point,
        }
    }
}

/// A case of the head's vector kernels: a random layer, an input vector
/// given as two parts (split at `split`) and the portable kernel's
/// activations for it.
pub(crate) struct VectorCase {
    pub layer: TestLayer,
    pub x: Vec<u8>,
    pub split: usize,
    pub want: Vec<i8>,
}

impl VectorCase {
    /// The case with its first part folded into the biases, as
    /// `Int8Model::prepare` folds the head's template half: each bias plus
    /// the row's first `split` weights times the first part (the portable
    /// dot product), for the kernels called with `skip = split` on the
    /// second part alone.
    pub(crate) fn folded_bias(&self) -> Vec<u8> {
        let (a, _) = self.x.split_at(self.split);
        let rows = super::rows(&self.layer.weights, self.x.len());
        let biases = crate::format::le_i32s(&self.layer.bias);
        rows.zip(biases)
            .flat_map(|(row, b)| {
                b.wrapping_add(super::dot(&row[..self.split], a))
                    .to_le_bytes()
            })
            .collect()
    }
}

/// The vector kernels' cases: one part or two, with and without a tail
/// past 16 (or 64) inputs, row counts that are and are not multiples of
/// four.
pub(crate) fn vector_cases(seed: u64) -> Vec<VectorCase> {
    let mut rng = SplitMix64(seed);
    [
        (8, 16, 4),
        (0, 40, 7),
        (256, 512, 256),
        (20, 41, 9),
        (100, 230, 13),
    ]
    .into_iter()
    .map(|(split, inputs, outputs)| {
        let layer = TestLayer::new(&mut rng, inputs, outputs, (-31, 31));
        let x: Vec<u8> = (0..inputs).map(|_| byte(&mut rng) as u8).collect();
        let mut want = std::vec![0i8; outputs];
        let sink = &mut Sink::Store {
            out: &mut want,
            outputs,
        };
        super::dense_tile(&layer.weights, inputs, layer.requant(), &x, sink);
        VectorCase {
            layer,
            x,
            split,
            want,
        }
    })
    .collect()
}

/// A case of the block kernels' layers on bytes: a random layer of
/// `inputs -> outputs` and a block's inputs, [`HOST_BLOCK`] rows of
/// `inputs` in `x`.
///
/// [`HOST_BLOCK`]: crate::arch::HOST_BLOCK
pub(crate) struct BlockCase {
    pub layer: TestLayer,
    pub inputs: usize,
    pub outputs: usize,
    pub x: Vec<i8>,
    pub what: &'static str,
}

/// The byte kernels' cases: widths that are and are not multiples of four
/// and of sixteen, output counts that are and are not multiples of the
/// four rows taken together, both requantization paths; inputs over the
/// whole int8 range, in its
/// lower or upper half only, and at either end. Then the largest
/// products: every weight -128 or 127, every input -128, -1 or 127, the
/// bias bringing the true accumulator to 400 and the output step dividing
/// by 8, so the activation is 50, far from either clamp (checked here on
/// the portable kernel): an accumulator off by more than 4 would show.
pub(crate) fn block_cases(seed: u64) -> Vec<BlockCase> {
    use crate::arch::HOST_BLOCK;
    let mut rng = SplitMix64(seed);
    let mut cases = Vec::new();
    let shapes = [
        (1, 1),
        (3, 64),
        (5, 3),
        (8, 8),
        (33, 17),
        (40, 9),
        (64, 64),
        (128, 256),
        (130, 5),
        (7, 10),
    ];
    for &(inputs, outputs) in &shapes {
        for shifts in [(-22, -2), (-31, 31)] {
            let n = HOST_BLOCK * inputs;
            let patterns: [(&str, Vec<i8>); 5] = [
                ("whole range", (0..n).map(|_| byte(&mut rng)).collect()),
                (
                    "lower half",
                    (0..n).map(|_| rng.int(-128, -1) as i8).collect(),
                ),
                (
                    "upper half",
                    (0..n).map(|_| rng.int(0, 127) as i8).collect(),
                ),
                ("all -128", std::vec![-128; n]),
                ("all 127", std::vec![127; n]),
            ];
            let layer = TestLayer::new(&mut rng, inputs, outputs, shifts);
            for (what, x) in patterns {
                cases.push(BlockCase {
                    layer: layer.clone(),
                    inputs,
                    outputs,
                    x,
                    what,
                });
            }
        }
    }
    let (inputs, outputs) = (128, 6);
    for weight in [-128i8, 127] {
        for x in [-128i8, -1, 127] {
            let mut layer = TestLayer::new(&mut rng, inputs, outputs, (-2, -2));
            layer.weights.fill(weight as u8);
            let dot = weight as i32 * x as i32 * inputs as i32;
            layer.bias = (0..outputs)
                .flat_map(|_| (400 - dot).to_le_bytes())
                .collect();
            layer.multiplier = (0..outputs)
                .flat_map(|_| (1i32 << 30).to_le_bytes())
                .collect();
            layer.zero_point = 0;
            let x = std::vec![x; HOST_BLOCK * inputs];
            let mut want = std::vec![i8::MIN; outputs];
            super::dense_tile(
                &layer.weights,
                inputs,
                layer.requant(),
                &x,
                &mut Sink::Pool(&mut want),
            );
            assert_eq!(
                want,
                std::vec![50; outputs],
                "the portable kernel's activation"
            );
            cases.push(BlockCase {
                layer,
                inputs,
                outputs,
                x,
                what: "extremes",
            });
        }
    }
    cases
}
