//! The x86-64 AVX2 (and AVX-512 VNNI) block encoder (`std` feature):
//! [`HOST_BLOCK`](crate::arch::HOST_BLOCK) points through every encoder
//! layer, each layer a small matrix product.
//!
//! The tile kernel ([`super::x86`]) multiplies one weight row with eight
//! points' activations along the input axis and must add each point's
//! eight partial sums horizontally, for every output. Here the vector
//! lanes run along the points instead, so no lane sum is ever needed:
//!
//! - the weights of every encoder layer but the pooled one are copied once
//!   per call into int16 rows padded to an even length (input `2j` in the
//!   low half of word `j`, input `2j + 1` in the high half);
//! - a layer's input is kept as int16 pairs *by point*: word `j * BLOCK +
//!   p` holds point `p`'s inputs `2j` and `2j + 1`. The first layer's
//!   input is the coordinates: `(x, y)` then `(z, 0)`;
//! - for two outputs at a time and every input pair ([`pairs`]), the two
//!   weight words are broadcast and `VPMADDWD` multiplies them with the
//!   pairs of eight points at once (16 multiplies, pairs summed into eight
//!   i32 lanes), half a block (four vectors of points) per weight word at
//!   a time, so the sixteen vectors of work stay in registers; the eight
//!   accumulators start from the biases;
//! - the output step runs on eight points at once, and the two outputs'
//!   activations are interleaved straight into the next layer's pairs; the
//!   last layer keeps each output's largest accumulator over the blocks
//!   ([`raise`]) and its output steps run once, after the last block
//!   (the step is non-decreasing, so that is the max-pool);
//! - the last (pooled) layer, most of the work, runs on bytes instead
//!   when its input is an int8 activation ([`bytes`]): `VPMADDUBSW` on
//!   the low seven bits of each input, a second pass only for the rare
//!   quads of inputs with the top bit set;
//! - on a CPU with AVX-512 VNNI the layers take another route: the first
//!   (the coordinates, int16) through [`wide`], `VPDPWSSD` on the same
//!   pairs, and every later one through [`vnni`], `VPDPBUSD` on byte quads
//!   of `x + 128` (64 multiply-adds an instruction, twice `VPDPWSSD`'s),
//!   each layer writing its activations straight into the next one's
//!   quads; sixteen points a vector, four vectors a block, four rows at a
//!   time.
//!
//! Every product and pair sum fits in i32 (`|w| <= 128`, `|x| <= 32767`),
//! and model loading bounds every partial sum (see [`super::dot`]), so the
//! result is the portable kernel's, bit for bit, in any order.

use super::{Requant, as_words};
use crate::arch::{Arch, HOST_BLOCK as BLOCK, INPUT_DIM};
use crate::fixed::OutputStep;
use crate::format::{Int8Layer, le_i32s};

mod bytes;
mod pairs;
mod vnni;
mod wide;
use bytes::{ByteLayer, pool_bytes};
use pairs::{Dest, layer, pair, widen};
use vnni::{Out, layer_bytes};
use wide::layer_wide;

/// A block encoder over a caller's scratch: the int16 weights, the row
/// sums of every layer after the first, the pooled layer's quad list when
/// it runs on bytes, and two activation buffers.
pub(crate) struct BlockEncoder<'w> {
    weights: &'w [u32],
    /// Each row's weight sum, for every layer after the first in order
    /// (their byte kernels take `-128 * sum` into the bias).
    sums: &'w [u32],
    pooled: Option<OnBytes<'w>>,
    /// The pooled layer's largest accumulators over the blocks so far
    /// ([`raise`]), and whether any block has been encoded.
    maxima: &'w mut [u32],
    blocks: bool,
    acts: (&'w mut [u32], &'w mut [u32]),
    /// The CPU has AVX-512 VNNI and BW: the first layer through
    /// [`layer_wide`], every later one through [`layer_bytes`] on byte
    /// quads, and only the first layer's weights are copied.
    vnni: bool,
}

/// The pooled layer's scratch when it runs on bytes with AVX2.
struct OnBytes<'w> {
    /// Room for the list of quads that take the high-bit pass.
    quads: &'w mut [u32],
    /// Room for its int16 weights, copied the first time a block has too
    /// many quads with a high bit for the byte kernel to pay (see
    /// [`pool_bytes`]).
    wide: &'w mut [u32],
    widened: bool,
}

impl<'w> BlockEncoder<'w> {
    /// Copies the encoder weights into `area` (at least
    /// [`Arch::host_block_len`] bytes) and returns the encoder; `None`,
    /// having done nothing that matters, without AVX2 or room.
    pub(crate) fn new(arch: &Arch, layers: &[Int8Layer<'_>], area: &'w mut [i8]) -> Option<Self> {
        Self::with_route(arch, layers, area, vnni::has_vnni())
    }

    /// [`Self::new`] on the VNNI kernels or not, as `vnni` says (it must
    /// not say so on a CPU without them).
    fn with_route(
        arch: &Arch,
        layers: &[Int8Layer<'_>],
        area: &'w mut [i8],
        vnni: bool,
    ) -> Option<Self> {
        if !std::is_x86_feature_detected!("avx2") || area.len() < arch.host_block_len() {
            return None;
        }
        let words = as_words(area);
        let sizes = arch.host_block_words();
        let (weights, rest) = words.split_at_mut_checked(sizes.weights)?;
        let (sums, rest) = rest.split_at_mut_checked(sizes.sums)?;
        let (quads, rest) = rest.split_at_mut_checked(sizes.quads)?;
        let (maxima, rest) = rest.split_at_mut_checked(sizes.maxima)?;
        maxima.fill(i32::MIN as u32);
        let (a, rest) = rest.split_at_mut_checked(sizes.buffer)?;
        let b = rest.get_mut(..sizes.buffer)?;
        // The AVX2 route reads only the pooled layer's sums (the last).
        let later = arch.encoder.len().saturating_sub(1);
        let mut free = &mut *sums;
        for (l, (shape, layer)) in arch.encoder_layers().zip(layers).enumerate().skip(1) {
            let (out, tail) = free.split_at_mut_checked(shape.outputs)?;
            if vnni || l == later {
                for (sum, row) in out.iter_mut().zip(super::rows(layer.weights, shape.inputs)) {
                    *sum = row.iter().map(|&w| w as i8 as i32).sum::<i32>() as u32;
                }
            }
            free = tail;
        }
        // A pooled layer on bytes: its int16 weights last, copied later if
        // at all. With VNNI only the first layer's are ever used.
        let last = arch.encoder_layers().last();
        let on_bytes = last.filter(|_| sizes.quads > 0);
        let later = on_bytes.map_or(0, |shape| shape.pair_words());
        let (weights, wide) = weights.split_at_mut_checked(sizes.weights.checked_sub(later)?)?;
        let widened = if vnni {
            1
        } else {
            arch.encoder
                .len()
                .saturating_sub(usize::from(on_bytes.is_some()))
        };
        let mut free = &mut *weights;
        for (shape, layer) in arch.encoder_layers().zip(layers).take(widened) {
            let (out, tail) = free.split_at_mut_checked(shape.pair_words())?;
            widen(layer.weights, shape.inputs, out);
            free = tail;
        }
        Some(BlockEncoder {
            weights,
            sums,
            pooled: on_bytes.map(|_| OnBytes {
                quads,
                wide,
                widened: false,
            }),
            maxima,
            blocks: false,
            acts: (a, b),
            vnni,
        })
    }

    /// Encodes a block of quantized points and max-pools the last layer's
    /// accumulators into the running maxima, which [`Self::pool`] then
    /// takes into a feature. `layers` holds each encoder layer's input and output
    /// widths, int8 weights and requantization, first to last, as in
    /// [`Self::new`].
    pub(crate) fn encode<'q>(
        &mut self,
        points: &[[i16; INPUT_DIM]; BLOCK],
        layers: impl Iterator<Item = (usize, usize, &'q [u8], Requant<'q>)>,
    ) {
        self.blocks = true;
        let (a, b) = (&mut *self.acts.0, &mut *self.acts.1);
        let (xy, z) = a.split_at_mut(BLOCK.min(a.len()));
        for ((xy, z), &[x, y, zc]) in xy.iter_mut().zip(z.iter_mut()).zip(points) {
            *xy = pair(x, y);
            *z = pair(zc, 0);
        }
        let (mut input, mut output) = (a, b);
        if self.vnni {
            // SAFETY: `BlockEncoder::new` found AVX-512 VNNI and BW (which
            // imply F), all `encode_vnni` requires.
            #[allow(unsafe_code)]
            unsafe {
                encode_vnni(self.weights, self.sums, input, output, layers, self.maxima)
            };
            return;
        }
        let mut weights = self.weights;
        let mut layers = layers.peekable();
        while let Some((inputs, outputs, bytes, q)) = layers.next() {
            let pairs = inputs.div_ceil(2);
            let last = layers.peek().is_none();
            if let (true, Some(on)) = (last, self.pooled.as_mut()) {
                let pooled = ByteLayer {
                    weights: bytes,
                    inputs,
                    // The pooled layer's sums are the last.
                    sums: self
                        .sums
                        .get(self.sums.len().saturating_sub(outputs)..)
                        .unwrap_or(&[]),
                };
                let maxima = &mut *self.maxima;
                // SAFETY: `BlockEncoder::new` found AVX2, all `pool_bytes`
                // and `layer` require.
                #[allow(unsafe_code)]
                unsafe {
                    if !pool_bytes(&pooled, q, input, output, on.quads, maxima) {
                        if !on.widened {
                            widen(bytes, inputs, on.wide);
                            on.widened = true;
                        }
                        layer(on.wide, pairs, q, input, Dest::Maxima(maxima));
                    }
                };
                return;
            }
            let (w, rest) = weights.split_at(weights.len().min(outputs * pairs));
            weights = rest;
            let dest = if last {
                Dest::Maxima(&mut *self.maxima)
            } else {
                Dest::Pairs(&mut *output)
            };
            // SAFETY: `BlockEncoder::new` found AVX2, all `layer` requires.
            #[allow(unsafe_code)]
            unsafe {
                layer(w, pairs, q, input, dest)
            };
            core::mem::swap(&mut input, &mut output);
        }
    }
}

impl BlockEncoder<'_> {
    /// Takes what the blocks left in the running maxima into `feature`,
    /// through the pooled layer's output steps `q`. Call it once the last
    /// block is in.
    pub(crate) fn pool(&self, q: Requant<'_>, feature: &mut [i8]) {
        if self.blocks {
            pool_maxima(self.maxima, q, feature);
        }
    }
}

/// [`BlockEncoder::encode`] with AVX-512 VNNI, from the coordinate pairs
/// in `input`: the first layer on them ([`layer_wide`], its int16
/// `weights`), every later one on the previous one's byte quads
/// ([`layer_bytes`], their row `sums` in order), `output` and `input`
/// taking turns; the pooled layer's largest accumulators into `maxima`.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
fn encode_vnni<'a, 'q>(
    weights: &[u32],
    mut sums: &[u32],
    mut input: &'a mut [u32],
    mut output: &'a mut [u32],
    layers: impl Iterator<Item = (usize, usize, &'q [u8], Requant<'q>)>,
    maxima: &mut [u32],
) {
    let mut layers = layers.peekable();
    let mut first = true;
    while let Some((inputs, outputs, bytes, q)) = layers.next() {
        let out = if layers.peek().is_none() {
            Out::Maxima(&mut *maxima)
        } else {
            Out::Quads(&mut *output)
        };
        if core::mem::take(&mut first) {
            let w = weights.get(..outputs * inputs.div_ceil(2)).unwrap_or(&[]);
            layer_wide(w, inputs.div_ceil(2), q, input, out);
        } else {
            let (s, rest) = sums.split_at(sums.len().min(outputs));
            sums = rest;
            let layer = ByteLayer {
                weights: bytes,
                inputs,
                sums: s,
            };
            if !layer_bytes(&layer, q, input, out) {
                return;
            }
        }
        core::mem::swap(&mut input, &mut output);
    }
}

/// Raises output `o`'s running maximum (an i32 in each word of `maxima`,
/// `i32::MIN` at first) to `acc`. The pooled layer keeps its largest
/// accumulators over the blocks and [`pool_maxima`] applies the output
/// steps once the last block is in: the step is non-decreasing (see
/// [`Sink::Pool`](super::Sink::Pool)), so the step of the largest accumulator is the largest
/// activation, and one step per output replaces one per output and block.
#[inline]
fn raise(maxima: &mut [u32], o: usize, acc: i32) {
    if let Some(slot) = maxima.get_mut(o)
        && acc > *slot as i32
    {
        *slot = acc as u32;
    }
}

/// Applies the pooled layer's output steps to the largest accumulators
/// that the blocks left in `maxima` and raises `feature` to each
/// activation.
fn pool_maxima(maxima: &[u32], q: Requant<'_>, feature: &mut [i8]) {
    let steps = le_i32s(q.multiplier).zip(q.shift);
    for ((f, &acc), (m, &s)) in feature.iter_mut().zip(maxima).zip(steps) {
        let v = OutputStep::new(m, s as i8, q.zero_point, q.act_min).apply(acc as i32);
        *f = (*f).max(v);
    }
}

#[cfg(test)]
mod tests {
    use super::super::Sink;
    use super::super::test_layer::TestLayer;
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// The whole block encoder, on the VNNI kernels (where the CPU has
    /// them) and on AVX2 alone, gives the pooled feature of the portable
    /// kernels over two blocks: encoders of one layer, of odd widths and of
    /// the embedded widths, both requantization paths.
    #[test]
    fn block_encoder_matches_portable_on_every_route() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let routes: &[bool] = if vnni::has_vnni() {
            &[false, true]
        } else {
            std::eprintln!("no AVX-512 VNNI on this CPU: its route not tested");
            &[false]
        };
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
                                let dot = w.iter().zip(p).fold(b, |a, (&w, &c)| {
                                    a.wrapping_add(w as i8 as i32 * c as i32)
                                });
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
                        super::super::dense_tile(&l.weights, shape.inputs, l.requant(), &x, sink);
                        x = out;
                    }
                    let last = shapes.last().unwrap().outputs;
                    for acts in x.chunks(last) {
                        for (f, &v) in want.iter_mut().zip(acts) {
                            *f = (*f).max(v);
                        }
                    }
                }
                for &vnni in routes {
                    let mut area = std::vec![0i8; arch.host_block_len()];
                    let mut encoder =
                        BlockEncoder::with_route(&arch, &layers, &mut area, vnni).unwrap();
                    let mut got = std::vec![i8::MIN; want.len()];
                    for points in &blocks {
                        let steps = shapes
                            .iter()
                            .zip(&random)
                            .map(|(s, l)| (s.inputs, s.outputs, &l.weights[..], l.requant()));
                        encoder.encode(points, steps);
                    }
                    encoder.pool(random.last().unwrap().requant(), &mut got);
                    assert_eq!(got, want, "{widths:?}, {shifts:?}, VNNI {vnni}");
                }
            }
        }
    }
}
