//! The block kernel's layers on aarch64 with the dot-product extension
//! (Armv8.2 `dotprod`: Cortex-A55/A76 and later, Apple M, Graviton 2+):
//! the first layer on the coordinates' int16 pairs, every later one on
//! byte quads, each writing its activations straight into the next one's
//! quads.
//!
//! As in the x86-64 block kernels, the vector lanes run along the points
//! (four to a vector), so no lane is ever summed across: a group of four
//! rows takes a quarter of the block at a time (sixteen points, four
//! vectors), sixteen accumulators in all.
//!
//! - A layer on bytes holds its input as signed byte quads by point (word
//!   `j * BLOCK + p` holds point `p`'s inputs `4j..4j + 4`; past the
//!   inputs the weights are zero, so what is there adds nothing). Each row
//!   is read sixteen weights (four quads) at a time, and `SDOT` by element
//!   adds into each point's lane the four products of its quad with quad
//!   `k` of the row (`sdot v.4s, x.16b, w.4b[k]`): one load of weights per
//!   sixteen `SDOT`s of the group. A row's last quads (past a multiple of
//!   sixteen inputs) are broadcast whole.
//! - The first layer holds the coordinates as int16 pairs by point, `(x,
//!   y)` then `(z, 0)`: `SMULL`/`SMULL2` of four points' pairs with a
//!   broadcast weight pair, then `ADDP` sums each point's two products.
//! - The output step runs on four points at once: the high word of the
//!   64-bit product as `SQDMULH` (the doubled product's high word) shifted
//!   right by one, exact for every multiplier model loading accepts (none
//!   is negative), the folded offset and the shift; then two
//!   saturating narrows (`SQXTN`, the clamp at 127 and -128), one byte
//!   table lookup from row order to point order and `SMAX` with the ReLU
//!   floor (the constants broadcast once a pass when all four rows take
//!   the fast step). The pooled layer keeps a vector of running maxima
//!   per row over the passes, reduced four rows at once into each
//!   output's largest accumulator ([`raise_group`], [`raise`]).
//!
//! Every product and pair sum fits in i32 (`|w| <= 128`, `|x| <= 32767`,
//! four byte products at most `4 * 128 * 128`), and model loading bounds
//! every partial sum (see [`super::super::dot`]), so the result is the
//! portable kernel's, bit for bit. `cargo xtask aarch64-test` runs the
//! tests under `qemu-aarch64` on a CPU with `dotprod`; without it the
//! encoder keeps to the tile kernel ([`super::super::neon`]).

use core::arch::aarch64::{
    int8x16_t, int32x4_t, vaddq_s32, vdupq_n_s32, vdupq_n_u32, vget_low_s16, vld1q_s8, vld1q_s32,
    vld1q_u8, vmaxq_s8, vmaxq_s32, vmull_high_s16, vmull_s16, vpaddq_s32, vpmaxq_s32, vqdmulhq_s32,
    vqmovn_high_s16, vqmovn_high_s32, vqmovn_s16, vqmovn_s32, vqtbl1q_s8, vreinterpretq_s8_s32,
    vreinterpretq_s8_u32, vreinterpretq_s16_s8, vreinterpretq_s16_u32, vshlq_s32, vshrq_n_s32,
    vst1q_s8, vst1q_s32,
};

use super::super::Requant;
pub(super) use super::super::neon::has_sdot;
use super::super::neon::{sdot, sdot_lane};
use super::{BLOCK, ByteLayer, Out, ROWS, group, quad, raise};
use crate::fixed::OutputStep;

/// Vectors of four points in a pass.
const PASS: usize = 4;

/// Points in a pass (a quarter of the block).
const PASS_POINTS: usize = 4 * PASS;

/// Passes over a block.
const PASSES: usize = BLOCK / PASS_POINTS;

/// A group's accumulators over a pass: rows by vectors of four points.
type Acc = [[int32x4_t; PASS]; ROWS];

/// The SDOT route's kernels: the first layer through [`layer_pairs`],
/// every later one through [`layer_bytes`].
pub(super) struct Kernels;

impl super::QuadKernels for Kernels {
    unsafe fn first(weights: &[u32], pairs: usize, q: Requant<'_>, input: &[u32], out: Out<'_>) {
        // SAFETY: NEON is part of every aarch64 CPU.
        unsafe { layer_pairs(weights, pairs, q, input, out) }
    }

    unsafe fn later(layer: &ByteLayer<'_>, q: Requant<'_>, input: &[u32], out: Out<'_>) -> bool {
        // SAFETY: the caller's (the CPU has `dotprod`).
        unsafe { layer_bytes(layer, q, input, out) }
    }
}

/// Accumulators starting from the rows' biases.
#[inline]
#[target_feature(enable = "neon")]
fn start(biases: [i32; ROWS]) -> Acc {
    let mut acc = [[vdupq_n_s32(0); PASS]; ROWS];
    for (acc, b) in acc.iter_mut().zip(biases) {
        *acc = [vdupq_n_s32(b); PASS];
    }
    acc
}

/// Four vectors of four points' words from `x` on (a pass of one input
/// row of a block).
///
/// # Safety
/// `x` must point at sixteen readable words.
#[inline]
#[target_feature(enable = "neon")]
unsafe fn load_pass(x: *const u32) -> [int8x16_t; PASS] {
    // SAFETY: the caller's; NEON loads need no alignment.
    unsafe {
        [
            vld1q_s8(x.cast()),
            vld1q_s8(x.add(4).cast()),
            vld1q_s8(x.add(8).cast()),
            vld1q_s8(x.add(12).cast()),
        ]
    }
}

/// The first layer (the coordinates, int16 pairs by point, `pairs x
/// BLOCK` words in `input`): `weights` holds its rows of `pairs` pair
/// words; the activations go to `out`. Does nothing when `input` or
/// `weights` is short.
#[target_feature(enable = "neon")]
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
        if rs.iter().any(|r| r.len() < pairs) {
            return;
        }
        let mut best = [vdupq_n_s32(i32::MIN); ROWS];
        for pass in 0..PASSES {
            let mut acc = start(biases);
            for j in 0..pairs {
                // SAFETY: `input` holds `pairs x BLOCK` words and `pass *
                // 16 + 16 <= BLOCK`; every row holds `pairs` words.
                let (x, w) = unsafe {
                    (
                        load_pass(input.as_ptr().add(j * BLOCK + pass * PASS_POINTS)),
                        rs.map(|r| *r.as_ptr().add(j)),
                    )
                };
                for (acc, w) in acc.iter_mut().zip(w) {
                    let w = vreinterpretq_s16_u32(vdupq_n_u32(w));
                    for (a, &x) in acc.iter_mut().zip(&x) {
                        let x = vreinterpretq_s16_s8(x);
                        // Each point's two products side by side, then
                        // summed pairwise: lanes are points again.
                        let low = vmull_s16(vget_low_s16(x), vget_low_s16(w));
                        let high = vmull_high_s16(x, w);
                        *a = vaddq_s32(*a, vpaddq_s32(low, high));
                    }
                }
            }
            finish(&acc, &steps, o, pass, &mut out, &mut best);
        }
        if let Out::Maxima(maxima) = &mut out {
            raise_group(maxima, o, &steps, best);
        }
    }
}

/// A layer whose input is an int8 activation, as signed byte quads by
/// point (`inputs.div_ceil(4) x BLOCK` words in `quads`); the activations
/// go to `out`. Returns `false` when `quads` or a weight row is short,
/// having written nothing in the first case.
#[target_feature(enable = "dotprod")]
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
    let (outputs, chunks) = (q.shift.len(), inputs / 16);
    for o in (0..outputs).step_by(ROWS) {
        let (rs, biases, steps) = group(layer.weights, inputs, q, o, outputs, &[]);
        if rs.iter().any(|r| r.len() < inputs) {
            // (Never for a loaded model: its rows are checked at load.)
            return false;
        }
        let mut best = [vdupq_n_s32(i32::MIN); ROWS];
        for pass in 0..PASSES {
            let mut acc = start(biases);
            // Plain pointers in the loops: a check per load (its `None`
            // path) made the compiler store every accumulator after every
            // step.
            let Some(x) = quads.get(pass * PASS_POINTS..) else {
                return false;
            };
            let x = x.as_ptr();
            for c in 0..chunks {
                // SAFETY: every row holds `inputs >= 16 c + 16` weights;
                // quad `4c + k < count` of the pass starts `(4c + k) BLOCK`
                // words on, and `quads` holds `count x BLOCK` words from
                // `x - pass * 16`, `pass * 16 + 16 <= BLOCK`.
                unsafe {
                    let w = rs.map(|r| vld1q_s8(r.as_ptr().add(16 * c).cast()));
                    let x = x.add(4 * c * BLOCK);
                    // (Plain calls: a loop over `k` cannot give `SDOT` its
                    // lane as a constant.)
                    lane_step::<0>(&mut acc, &w, &load_pass(x));
                    lane_step::<1>(&mut acc, &w, &load_pass(x.add(BLOCK)));
                    lane_step::<2>(&mut acc, &w, &load_pass(x.add(2 * BLOCK)));
                    lane_step::<3>(&mut acc, &w, &load_pass(x.add(3 * BLOCK)));
                }
            }
            for j in 4 * chunks..count {
                let w = rs.map(|r| quad(r, j));
                // SAFETY: as above, `j < count`.
                let x = unsafe { load_pass(x.add(j * BLOCK)) };
                for (acc, w) in acc.iter_mut().zip(w) {
                    let w = broadcast(w);
                    for (a, &x) in acc.iter_mut().zip(&x) {
                        // SAFETY: this function requires `dotprod`.
                        *a = unsafe { sdot(*a, w, x) };
                    }
                }
            }
            finish(&acc, &steps, o, pass, &mut out, &mut best);
        }
        if let Out::Maxima(maxima) = &mut out {
            raise_group(maxima, o, &steps, best);
        }
    }
    true
}

/// A weight quad in every lane.
#[inline]
#[target_feature(enable = "neon")]
fn broadcast(quad: i32) -> int8x16_t {
    vreinterpretq_s8_s32(vdupq_n_s32(quad))
}

/// Adds to the group's accumulators the products of quad `K` of each row's
/// sixteen weights `w` with the pass's points' quads `x`.
#[inline]
#[target_feature(enable = "dotprod")]
fn lane_step<const K: i32>(acc: &mut Acc, w: &[int8x16_t; ROWS], x: &[int8x16_t; PASS]) {
    for (acc, &w) in acc.iter_mut().zip(w) {
        for (a, &x) in acc.iter_mut().zip(x) {
            // SAFETY: this function requires `dotprod`.
            *a = unsafe { sdot_lane::<K>(*a, x, w) };
        }
    }
}

/// The end of a pass of a group of rows `o..o + ROWS`: each row's
/// accumulators raise its vector of running maxima in `best` when `out`
/// is the max-pool ([`raise_group`] takes them into it after the last
/// pass), or go through the row's step into the next layer's quads (word
/// `o / 4` of each point of the pass). Not inlined: it is most of the code
/// and runs once per group and pass.
#[inline(never)]
#[target_feature(enable = "neon")]
fn finish(
    acc: &Acc,
    steps: &[Option<OutputStep>; ROWS],
    o: usize,
    pass: usize,
    out: &mut Out<'_>,
    best: &mut [int32x4_t; ROWS],
) {
    match out {
        Out::Maxima(_) => {
            for (b, acc) in best.iter_mut().zip(acc) {
                for &a in acc {
                    *b = vmaxq_s32(*b, a);
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
            // The ReLU floor in each row's byte of a word; a missing row's
            // byte stays 0 under -128.
            let floor = steps.map(|s| s.map_or(i8::MIN, |s| s.act_min()) as u8);
            let floor = vreinterpretq_s8_u32(vdupq_n_u32(u32::from_le_bytes(floor)));
            let words = words.as_chunks_mut::<4>().0.iter_mut();
            let fast = steps.map(|s| s.and_then(|s| s.fast_parts()));
            if let [Some(f0), Some(f1), Some(f2), Some(f3)] = fast {
                // Every row on the fast path (the usual case): its constants
                // once for the pass, straight-line steps.
                let parts = [f0, f1, f2, f3];
                let mut k = [[vdupq_n_s32(0); 3]; ROWS];
                for (k, &(m, offset, high_shift, _)) in k.iter_mut().zip(&parts) {
                    *k = [
                        vdupq_n_s32(m),
                        vdupq_n_s32(offset),
                        vdupq_n_s32(-(high_shift as i32)),
                    ];
                }
                for (v, words) in words.enumerate() {
                    let mut rows = [vdupq_n_s32(0); ROWS];
                    for (r, y) in rows.iter_mut().enumerate() {
                        if let (Some(&a), Some(&[m, offset, shift])) = (acc[r].get(v), k.get(r)) {
                            *y = high_step(a, m, offset, shift);
                        }
                    }
                    store_quads(words, rows, floor);
                }
            } else {
                for (v, words) in words.enumerate() {
                    let mut rows = [vdupq_n_s32(0); ROWS];
                    for ((y, acc), step) in rows.iter_mut().zip(acc).zip(steps) {
                        if let (Some(step), Some(&a)) = (step, acc.get(v)) {
                            *y = stepped(a, step);
                        }
                    }
                    store_quads(words, rows, floor);
                }
            }
        }
    }
}

/// Four rows' stepped accumulators of four points as the next layer's
/// four quad words: saturating narrows (the clamp to int8), one byte
/// table lookup from row order to point order, and `SMAX` with `floor`
/// (each row's ReLU floor in its byte).
#[inline]
#[target_feature(enable = "neon")]
fn store_quads(words: &mut [u32; 4], rows: [int32x4_t; ROWS], floor: int8x16_t) {
    // Byte `4p + r` of a word set comes from byte `4r + p`.
    let order: [u8; 16] = [0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15];
    // SAFETY: 16 bytes; NEON loads need no alignment.
    let order = unsafe { vld1q_u8(order.as_ptr()) };
    let [r0, r1, r2, r3] = rows;
    let low = vqmovn_high_s32(vqmovn_s32(r0), r1);
    let high = vqmovn_high_s32(vqmovn_s32(r2), r3);
    let by_row = vqmovn_high_s16(vqmovn_s16(low), high);
    let word = vmaxq_s8(vqtbl1q_s8(by_row, order), floor);
    // SAFETY: `words` is four words (16 bytes); NEON stores need no
    // alignment.
    unsafe { vst1q_s8(words.as_mut_ptr().cast(), word) };
}

/// Raises the running maxima of rows `o..o + ROWS` (those with a step)
/// to the largest lanes of their vectors in `best`: two rounds of
/// pairwise maxima (`SMAXP`) leave lane `r` holding row `r`'s largest.
#[inline]
#[target_feature(enable = "neon")]
fn raise_group(
    maxima: &mut [u32],
    o: usize,
    steps: &[Option<OutputStep>; ROWS],
    best: [int32x4_t; ROWS],
) {
    let [m0, m1, m2, m3] = best;
    let m = vpmaxq_s32(vpmaxq_s32(m0, m1), vpmaxq_s32(m2, m3));
    let mut largest = [0i32; ROWS];
    // SAFETY: `largest` is four i32 (16 bytes); NEON stores need no
    // alignment.
    unsafe { vst1q_s32(largest.as_mut_ptr(), m) };
    for (r, (&v, step)) in largest.iter().zip(steps).enumerate() {
        if step.is_some() {
            raise(maxima, o + r, v);
        }
    }
}

/// The fast step of [`stepped`]: `m`, `offset` and `-high_shift` in
/// every lane.
#[inline]
#[target_feature(enable = "neon")]
fn high_step(acc: int32x4_t, m: int32x4_t, offset: int32x4_t, shift: int32x4_t) -> int32x4_t {
    let hi = vshrq_n_s32::<1>(vqdmulhq_s32(acc, m));
    vshlq_s32(vaddq_s32(hi, offset), shift)
}

/// `OutputStep::apply` on four accumulators but for the clamp (the
/// caller's): on the fast path `hi(acc * m)` as `SQDMULH` (the high word
/// of `2 acc m`, which saturates only when both are `i32::MIN`, and model
/// loading rejects negative multipliers) shifted right by one, then the
/// folded offset and the arithmetic shift, the same integers as the
/// scalar step; lane by lane (clamped, which changes nothing after) on the
/// general path.
#[inline]
#[target_feature(enable = "neon")]
fn stepped(acc: int32x4_t, step: &OutputStep) -> int32x4_t {
    match step.fast_parts() {
        Some((m, offset, high_shift, _)) => high_step(
            acc,
            vdupq_n_s32(m),
            vdupq_n_s32(offset),
            vdupq_n_s32(-(high_shift as i32)),
        ),
        _ => {
            let mut lanes = [0i32; 4];
            // SAFETY: `lanes` is four i32 (16 bytes); NEON loads and
            // stores need no alignment.
            unsafe {
                vst1q_s32(lanes.as_mut_ptr(), acc);
                let lanes = lanes.map(|a| step.apply(a) as i32);
                vld1q_s32(lanes.as_ptr())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::test_layer::block_cases;
    use super::super::area::widen;
    use super::super::tests::{check_layer, pairs_by_point, quads_by_point};
    use super::*;

    /// Both layers of the SDOT route (the byte quads one, and the int16
    /// pairs one on the same values) give the portable kernel's
    /// activations, stored and pooled, on every case of [`block_cases`];
    /// what lies past a layer's inputs in its quads must not matter.
    #[test]
    fn sdot_layers_match_portable() {
        if !has_sdot() {
            std::eprintln!("no dot-product extension on this CPU: the SDOT kernels not tested");
            return;
        }
        for c in block_cases(38) {
            let (q, inputs) = (c.layer.requant(), c.inputs);
            let quads = quads_by_point(&c.x, inputs, 0x5A, 0);
            let layer = ByteLayer {
                weights: &c.layer.weights,
                inputs,
                sums: &[],
            };
            // SAFETY: the CPU has `dotprod` (checked above).
            check_layer(&c, "bytes", 0, &|out| {
                assert!(unsafe { layer_bytes(&layer, q, &quads, out) }, "buffers")
            });
            let pairs = pairs_by_point(&c.x, inputs);
            let mut wide = std::vec![0u32; c.outputs * inputs.div_ceil(2)];
            widen(&c.layer.weights, inputs, &mut wide);
            // SAFETY: NEON is part of every aarch64 CPU.
            check_layer(&c, "pairs", 0, &|out| unsafe {
                layer_pairs(&wide, inputs.div_ceil(2), q, &pairs, out)
            });
        }
    }
}
