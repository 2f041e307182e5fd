//! The block kernel's layers with AVX-VNNI: `VPDPBUSD` and `VPDPWSSD` on
//! 256-bit vectors (VEX), for CPUs that have them without AVX-512 (Intel's
//! client cores from Alder Lake on, Sierra Forest); a CPU with AVX-512
//! VNNI takes [`super::vnni`] instead.
//!
//! The same layers as the AVX-512 route, on half-width vectors and the
//! sixteen vector registers of AVX2: the first layer on the coordinates'
//! int16 pairs (`VPDPWSSD`), every later one on byte quads of `x + 128`
//! (`VPDPBUSD`, the bias taking `-128` times the row's weight sum), each
//! writing its activations straight into the next one's quads. A group of
//! four rows takes a quarter of the block at a time (sixteen points, two
//! vectors of eight), eight accumulators; each row's weight quad is
//! broadcast from memory. The output step is the AVX2 kernel's
//! ([`activations`]), then two saturating packs and one byte shuffle put
//! the four rows' bytes in point order, as on the AVX-512 route.
//!
//! The sums are the portable kernel's exact integers (products and pair
//! sums fit in i32, and model loading bounds every partial sum, see
//! [`super::super::dot`]), so the results are its bits.

use core::arch::x86_64::{
    __m256i, _mm256_dpbusd_avx_epi32, _mm256_dpwssd_avx_epi32, _mm256_loadu_si256,
    _mm256_max_epi32, _mm256_packs_epi16, _mm256_packs_epi32, _mm256_set1_epi32, _mm256_setr_epi8,
    _mm256_setzero_si256, _mm256_shuffle_epi8, _mm256_storeu_si256, _mm256_xor_si256,
};

use super::super::Requant;
use super::super::x86::{activations, max};
use super::{BLOCK, ByteLayer, Out, ROWS, group, quad, raise};
use crate::fixed::OutputStep;

/// Vectors of eight points in a pass.
const PASS: usize = 2;

/// Points in a pass (a quarter of the block).
const PASS_POINTS: usize = 8 * PASS;

/// Passes over a block.
const PASSES: usize = BLOCK / PASS_POINTS;

/// A group's accumulators over a pass: rows by vectors of eight points.
type Acc = [[__m256i; PASS]; ROWS];

/// Whether the CPU has AVX-VNNI (and AVX2, for the output step).
pub(super) fn has_avxvnni() -> bool {
    std::is_x86_feature_detected!("avxvnni") && std::is_x86_feature_detected!("avx2")
}

/// The AVX-VNNI route's kernels: the first layer through
/// [`layer_pairs`], every later one through [`layer_bytes`].
pub(super) struct Kernels;

#[allow(unsafe_code)]
impl super::QuadKernels for Kernels {
    unsafe fn first(weights: &[u32], pairs: usize, q: Requant<'_>, input: &[u32], out: Out<'_>) {
        // SAFETY: the caller's (AVX-VNNI and AVX2).
        unsafe { layer_pairs(weights, pairs, q, input, out) }
    }

    unsafe fn later(layer: &ByteLayer<'_>, q: Requant<'_>, input: &[u32], out: Out<'_>) -> bool {
        // SAFETY: as above.
        unsafe { layer_bytes(layer, q, input, out) }
    }
}

/// Accumulators starting from the rows' biases.
#[inline]
#[target_feature(enable = "avx2")]
fn start(biases: [i32; ROWS]) -> Acc {
    let mut acc = [[_mm256_setzero_si256(); PASS]; ROWS];
    for (acc, b) in acc.iter_mut().zip(biases) {
        *acc = [_mm256_set1_epi32(b); PASS];
    }
    acc
}

/// Pass `pass` of one input row of a block (`BLOCK` words, one per point)
/// as two vectors of eight points' words.
#[inline]
#[target_feature(enable = "avx2")]
fn load_pass(row: &[u32; BLOCK], pass: usize) -> [__m256i; PASS] {
    let x = row
        .get(pass * PASS_POINTS..)
        .and_then(|x| x.first_chunk::<PASS_POINTS>())
        .unwrap_or(&[0; PASS_POINTS]);
    let (a, b) = x.split_at(8);
    // SAFETY: `a` and `b` are eight words (32 bytes) each; unaligned loads
    // are allowed.
    #[allow(unsafe_code)]
    unsafe {
        [
            _mm256_loadu_si256(a.as_ptr().cast()),
            _mm256_loadu_si256(b.as_ptr().cast()),
        ]
    }
}

/// The first layer (the coordinates, int16 pairs by point, `pairs x
/// BLOCK` words in `input`): `weights` holds its rows of `pairs` pair
/// words; `VPDPWSSD` adds both products of a point's pair with a broadcast
/// weight pair to its lane. The activations go to `out`.
#[target_feature(enable = "avx2,avxvnni")]
pub(super) fn layer_pairs(
    weights: &[u32],
    pairs: usize,
    q: Requant<'_>,
    input: &[u32],
    mut out: Out<'_>,
) {
    let Some(input) = input.get(..pairs * BLOCK) else {
        return;
    };
    let outputs = q.shift.len();
    for o in (0..outputs).step_by(ROWS) {
        let (rs, biases, steps) = group(weights, pairs, q, o, outputs, &[]);
        let [r0, r1, r2, r3] = rs;
        for pass in 0..PASSES {
            let mut acc = start(biases);
            let columns = r0.iter().zip(r1).zip(r2).zip(r3);
            for ((((&a, &b), &c), &d), x) in columns.zip(input.as_chunks::<BLOCK>().0) {
                step(&mut acc, [a, b, c, d], &load_pass(x, pass), Product::Pairs);
            }
            finish(&acc, &steps, o, pass, &mut out);
        }
    }
}

/// A layer whose input is an int8 activation, as byte quads of `x + 128`
/// by point (`inputs.div_ceil(4) x BLOCK` words in `quads`); the rows'
/// weight sums in `layer`. The activations go to `out`. Returns `false`,
/// having written nothing, when `quads` is short.
#[target_feature(enable = "avx2,avxvnni")]
pub(super) fn layer_bytes(
    layer: &ByteLayer<'_>,
    q: Requant<'_>,
    quads: &[u32],
    mut out: Out<'_>,
) -> bool {
    let (inputs, count) = (layer.inputs, layer.inputs.div_ceil(4));
    let Some(quads) = quads.get(..count * BLOCK) else {
        return false;
    };
    let (quads, outputs, full) = (quads.as_chunks::<BLOCK>().0, q.shift.len(), inputs / 4);
    for o in (0..outputs).step_by(ROWS) {
        let (rs, biases, steps) = group(layer.weights, inputs, q, o, outputs, layer.sums);
        let [r0, r1, r2, r3] = rs.map(|r| r.as_chunks::<4>().0);
        for pass in 0..PASSES {
            let mut acc = start(biases);
            let words = r0.iter().zip(r1).zip(r2).zip(r3);
            for ((((&a, &b), &c), &d), x) in words.zip(quads) {
                let w = [a, b, c, d].map(i32::from_le_bytes).map(|w| w as u32);
                step(&mut acc, w, &load_pass(x, pass), Product::Bytes);
            }
            // The rows' last, partial quad.
            if let Some(x) = quads.get(full).filter(|_| full < count) {
                let w = rs.map(|r| quad(r, full) as u32);
                step(&mut acc, w, &load_pass(x, pass), Product::Bytes);
            }
            finish(&acc, &steps, o, pass, &mut out);
        }
    }
    true
}

/// Which products a step adds.
#[derive(Clone, Copy)]
enum Product {
    /// `VPDPWSSD`: int16 pairs.
    Pairs,
    /// `VPDPBUSD`: unsigned byte quads (the inputs) by signed ones.
    Bytes,
}

/// Adds to the rows' accumulators over the pass the products of their
/// weight words `w` (broadcast) with the pass's input words `x`.
#[inline]
#[target_feature(enable = "avx2,avxvnni")]
fn step(acc: &mut Acc, w: [u32; ROWS], x: &[__m256i; PASS], product: Product) {
    for (acc, w) in acc.iter_mut().zip(w) {
        let w = _mm256_set1_epi32(w as i32);
        for (a, &x) in acc.iter_mut().zip(x) {
            *a = match product {
                Product::Pairs => _mm256_dpwssd_avx_epi32(*a, x, w),
                Product::Bytes => _mm256_dpbusd_avx_epi32(*a, x, w),
            };
        }
    }
}

/// The end of a pass of a group of rows `o..o + ROWS`: each row with a
/// step takes its accumulators to `out`, the largest to the running
/// maxima or all through the step into the next layer's quads (word `o /
/// 4` of each point of the pass, plus 128).
#[inline(never)]
#[target_feature(enable = "avx2")]
fn finish(acc: &Acc, steps: &[Option<OutputStep>; ROWS], o: usize, pass: usize, out: &mut Out<'_>) {
    match out {
        Out::Maxima(maxima) => {
            for (r, (&[a, b], step)) in acc.iter().zip(steps).enumerate() {
                if step.is_some() {
                    raise(maxima, o + r, max(_mm256_max_epi32(a, b)));
                }
            }
        }
        Out::Quads(quads) => {
            let Some(words) = quads
                .get_mut(o / ROWS * BLOCK + pass * PASS_POINTS..)
                .and_then(|q| q.first_chunk_mut::<PASS_POINTS>())
            else {
                return;
            };
            // In each 128-bit lane, byte `4p + r` from byte `4r + p`.
            let by_point = _mm256_setr_epi8(
                0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15, 0, 4, 8, 12, 1, 5, 9, 13, 2,
                6, 10, 14, 3, 7, 11, 15,
            );
            for (v, words) in words.as_chunks_mut::<8>().0.iter_mut().enumerate() {
                // Each row's activations (0 for a missing row).
                let mut rows = [_mm256_setzero_si256(); ROWS];
                for ((y, acc), step) in rows.iter_mut().zip(acc).zip(steps) {
                    if let (Some(step), Some(&a)) = (step, acc.get(v)) {
                        *y = activations(a, step);
                    }
                }
                let [r0, r1, r2, r3] = rows;
                let by_row =
                    _mm256_packs_epi16(_mm256_packs_epi32(r0, r1), _mm256_packs_epi32(r2, r3));
                // x + 128 is x with its top bit flipped.
                let word = _mm256_xor_si256(
                    _mm256_shuffle_epi8(by_row, by_point),
                    _mm256_set1_epi32(0x8080_8080_u32 as i32),
                );
                // SAFETY: `words` is eight words (32 bytes); unaligned
                // stores are allowed.
                #[allow(unsafe_code)]
                unsafe {
                    _mm256_storeu_si256(words.as_mut_ptr().cast(), word)
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::test_layer::block_cases;
    use super::super::tests::{check_layer, pairs_by_point, quads_by_point};
    use super::super::widen;
    use super::*;
    use std::vec::Vec;

    /// Both layers of the AVX-VNNI route give the portable kernel's
    /// activations, stored and pooled, on every case of [`block_cases`];
    /// what lies past a layer's inputs in its quads must not matter.
    #[test]
    fn avxvnni_layers_match_portable() {
        if !has_avxvnni() {
            std::eprintln!("no AVX-VNNI on this CPU: its block kernels not tested");
            return;
        }
        for c in block_cases(41) {
            let (q, inputs) = (c.layer.requant(), c.inputs);
            let sums: Vec<u32> = super::super::super::rows(&c.layer.weights, inputs)
                .map(super::super::row_sum)
                .collect();
            let layer = ByteLayer {
                weights: &c.layer.weights,
                inputs,
                sums: &sums,
            };
            let quads = quads_by_point(&c.x, inputs, 0x5A, 0x80);
            // SAFETY: the CPU has AVX-VNNI and AVX2 (checked above).
            #[allow(unsafe_code)]
            check_layer(&c, "bytes", 0x80, &|out| {
                assert!(unsafe { layer_bytes(&layer, q, &quads, out) }, "buffers")
            });
            let pairs = pairs_by_point(&c.x, inputs);
            let mut wide = std::vec![0u32; c.outputs * inputs.div_ceil(2)];
            widen(&c.layer.weights, inputs, &mut wide);
            // SAFETY: as above.
            #[allow(unsafe_code)]
            check_layer(&c, "pairs", 0x80, &|out| unsafe {
                layer_pairs(&wide, inputs.div_ceil(2), q, &pairs, out)
            });
        }
    }
}
