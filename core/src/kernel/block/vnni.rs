//! The block kernel's layers on byte quads with AVX-512 VNNI
//! (`VPDPBUSD`): every encoder layer after the first, when the CPU has it.

use core::arch::x86_64::{
    __m512i, _mm_cvtsi32_si128, _mm_max_epi32, _mm_setr_epi8, _mm_storeu_si128,
    _mm256_castsi256_si128, _mm256_extracti128_si256, _mm256_max_epi32, _mm512_add_epi32,
    _mm512_broadcast_i32x4, _mm512_castsi512_si256, _mm512_dpbusd_epi32, _mm512_extracti64x4_epi64,
    _mm512_loadu_si512, _mm512_mask_shuffle_epi32, _mm512_max_epi8, _mm512_max_epi32,
    _mm512_mul_epi32, _mm512_packs_epi16, _mm512_packs_epi32, _mm512_set1_epi32,
    _mm512_setzero_si512, _mm512_shuffle_epi8, _mm512_sra_epi32, _mm512_srli_epi64,
    _mm512_storeu_si512, _mm512_unpackhi_epi32, _mm512_unpackhi_epi64, _mm512_unpacklo_epi32,
    _mm512_unpacklo_epi64, _mm512_xor_si512,
};

pub(super) use super::super::x86::has_vnni;
use super::super::{Requant, rows};

use super::{BLOCK, ByteLayer, Out, ROWS, group, quad, raise};
use crate::fixed::OutputStep;

/// Vectors of sixteen points in a block.
pub(super) const WIDE: usize = BLOCK / 16;

/// The VNNI route's kernels: the first layer through
/// [`super::wide::layer_wide`], every later one through [`layer_bytes`].
pub(super) struct Kernels;

#[allow(unsafe_code)]
impl super::QuadKernels for Kernels {
    unsafe fn first(weights: &[u32], pairs: usize, q: Requant<'_>, input: &[u32], out: Out<'_>) {
        // SAFETY: the caller's (AVX-512 VNNI and BW, which imply F).
        unsafe { super::wide::layer_wide(weights, pairs, q, input, out) }
    }

    unsafe fn later(layer: &ByteLayer<'_>, q: Requant<'_>, input: &[u32], out: Out<'_>) -> bool {
        // SAFETY: as above.
        unsafe { layer_bytes(layer, q, input, out) }
    }
}

/// A layer whose input is an int8 activation, on a CPU with AVX-512 VNNI.
/// `VPDPBUSD` multiplies 64 unsigned bytes by 64 signed ones and adds each
/// lane's four products to its i32 accumulator, with no intermediate
/// saturation, so no input needs splitting as in
/// [`super::bytes::pool_bytes`]:
///
/// - each input `x` is held as `u = x + 128` (0..=255) and the bias takes
///   `-128 * sum(w)`, so `b + sum(w x) = b - 128 sum(w) + sum(w u)`;
/// - `quads` holds the inputs as byte quads by point (word `j * BLOCK + p`
///   holds point `p`'s inputs `4j..4j + 4`; past `inputs` the weights are
///   zero, so whatever is there adds nothing), four vectors of sixteen
///   points per quad, as [`Out::Quads`] writes them;
/// - four rows at a time share each load: each row's weight quad is
///   broadcast and `VPDPBUSD` adds 64 products into sixteen points' lanes,
///   sixteen accumulators in all, then [`finish`] requantizes them into the
///   next layer's quads or takes each row's largest for the max-pool.
///
/// Each lane's four products are at most `4 * 255 * 128` in magnitude,
/// and the accumulator is the portable kernel's (its sums wrap in i32 the
/// same way and model loading bounds them), so the activations are too.
/// Returns `false`, having written nothing, when `quads` is short.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) fn layer_bytes(
    layer: &ByteLayer<'_>,
    q: Requant<'_>,
    quads: &[u32],
    mut out: Out<'_>,
) -> bool {
    let (inputs, full) = (layer.inputs, layer.inputs / 4);
    let Some(quads) = quads.get(..inputs.div_ceil(4) * BLOCK) else {
        return false;
    };
    let outputs = layer.sums.len();
    for o in (0..outputs).step_by(ROWS) {
        let (rs, biases, steps) = group(layer.weights, inputs, q, o, outputs, layer.sums);
        let mut acc = [[_mm512_setzero_si512(); WIDE]; ROWS];
        for (acc, b) in acc.iter_mut().zip(biases) {
            *acc = [_mm512_set1_epi32(b); WIDE];
        }
        let [r0, r1, r2, r3] = rs;
        // (Plain loops: a closure would not inherit the target features,
        // and its intrinsics would become calls.)
        let words = r0.as_chunks::<4>().0.iter();
        let words = words.zip(r1.as_chunks::<4>().0);
        let words = words.zip(r2.as_chunks::<4>().0);
        let words = words.zip(r3.as_chunks::<4>().0);
        let mut x = rows(quads, BLOCK);
        for (((&a, &b), &c), &d) in words {
            let w = [a, b, c, d].map(i32::from_le_bytes);
            if let Some(x) = x.next() {
                dot_step(&mut acc, w, x);
            }
        }
        // The rows' last, partial quad.
        if let Some(x) = x.next() {
            let w = [r0, r1, r2, r3].map(|r| quad(r, full));
            dot_step(&mut acc, w, x);
        }
        finish(acc, &steps, o, &mut out);
    }
    true
}

/// Adds to `ROWS` rows' accumulators over the block the products of their
/// weight quads `w` with the byte quads `x` (one word per point).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
fn dot_step(acc: &mut [[__m512i; WIDE]; ROWS], w: [i32; ROWS], x: &[u32]) {
    let Some(xs) = block_vectors(x) else {
        return;
    };
    for (acc, &w) in acc.iter_mut().zip(&w) {
        let w = _mm512_set1_epi32(w);
        for (a, &x) in acc.iter_mut().zip(&xs) {
            *a = _mm512_dpbusd_epi32(*a, x, w);
        }
    }
}

/// A block's words (one per point) as vectors of sixteen points; `None`
/// when `x` is short.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) fn block_vectors(x: &[u32]) -> Option<[__m512i; WIDE]> {
    let x = x.first_chunk::<BLOCK>()?;
    // (A block of another size than four vectors fails to compile here.)
    let [a, b, c, d]: &[[u32; 16]; WIDE] = x.as_chunks::<16>().0.try_into().ok()?;
    // SAFETY: each of `a..d` is sixteen words (64 bytes); unaligned loads
    // are allowed.
    #[allow(unsafe_code)]
    let xs = unsafe { [a, b, c, d].map(|v| _mm512_loadu_si512(v.as_ptr().cast())) };
    Some(xs)
}

/// The end of a group of rows `o..o + ROWS` (here and in [`super::wide`]):
/// each row with a step takes its accumulators over the block to `out`,
/// the largest to the running maxima or all through the step into the
/// next layer's quads, word `o / 4` of each point. Not inlined: taking the accumulators by reference in the caller
/// would keep them in memory in its loop.
#[inline(never)]
#[target_feature(enable = "avx512f,avx512bw")]
pub(super) fn finish(
    acc: [[__m512i; WIDE]; ROWS],
    steps: &[Option<OutputStep>; ROWS],
    o: usize,
    out: &mut Out<'_>,
) {
    match out {
        Out::Maxima(maxima) => {
            // Each row's largest lane over its vectors, then the four rows
            // at once: within each 128-bit block, pairs of lanes, then pairs
            // of pairs, leave lane r holding row r's largest; then across
            // the blocks.
            let m = acc.map(|a| {
                let [first, rest @ ..] = a;
                let mut m = first;
                for v in rest {
                    m = _mm512_max_epi32(m, v);
                }
                m
            });
            let t0 = _mm512_max_epi32(
                _mm512_unpacklo_epi32(m[0], m[1]),
                _mm512_unpackhi_epi32(m[0], m[1]),
            );
            let t1 = _mm512_max_epi32(
                _mm512_unpacklo_epi32(m[2], m[3]),
                _mm512_unpackhi_epi32(m[2], m[3]),
            );
            let u = _mm512_max_epi32(_mm512_unpacklo_epi64(t0, t1), _mm512_unpackhi_epi64(t0, t1));
            let v = _mm256_max_epi32(_mm512_castsi512_si256(u), _mm512_extracti64x4_epi64::<1>(u));
            let w = _mm_max_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
            let mut largest = [0i32; ROWS];
            // SAFETY: `largest` is four i32 (16 bytes); unaligned stores
            // are allowed.
            #[allow(unsafe_code)]
            unsafe {
                _mm_storeu_si128(largest.as_mut_ptr().cast(), w)
            };
            for (r, (&v, step)) in largest.iter().zip(steps).enumerate() {
                if step.is_some() {
                    raise(maxima, o + r, v);
                }
            }
        }
        Out::Quads(quads) => {
            let Some(words) = quads
                .get_mut(o / ROWS * BLOCK..)
                .and_then(|q| q.first_chunk_mut::<BLOCK>())
            else {
                return;
            };
            // The ReLU floor in each row's byte of a word; a missing row's
            // byte stays 0 under -128.
            let floor = steps.map(|s| s.map_or(i8::MIN, |s| s.act_min()) as u8);
            let floor = _mm512_set1_epi32(i32::from_le_bytes(floor));
            let words = words.as_chunks_mut::<16>().0.iter_mut();
            let fast = steps.map(|s| s.and_then(|s| s.fast_parts()));
            if let [Some(f0), Some(f1), Some(f2), Some(f3)] = fast {
                // Every row on the fast path (the usual case): its constants
                // once for the group, straight-line steps.
                let parts = [f0, f1, f2, f3];
                let mut m = [_mm512_setzero_si512(); ROWS];
                let mut offset = [_mm512_setzero_si512(); ROWS];
                for ((m, offset), &(mr, or, _, _)) in m.iter_mut().zip(&mut offset).zip(&parts) {
                    *m = _mm512_set1_epi32(mr);
                    *offset = _mm512_set1_epi32(or);
                }
                for (v, words) in words.enumerate() {
                    let mut rows = [_mm512_setzero_si512(); ROWS];
                    for (r, y) in rows.iter_mut().enumerate() {
                        if let (Some(&a), Some(&(_, _, shift, _))) = (acc[r].get(v), parts.get(r)) {
                            *y = high_step(a, m[r], offset[r], shift);
                        }
                    }
                    store_quads(words, rows, floor);
                }
            } else {
                for (v, words) in words.enumerate() {
                    // Each row's stepped accumulators (0 for a missing row).
                    let mut rows = [_mm512_setzero_si512(); ROWS];
                    for ((y, acc), step) in rows.iter_mut().zip(&acc).zip(steps) {
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

/// Four rows' stepped accumulators of sixteen points as the next layer's
/// sixteen quad words ([`pack_quads`]), floored by `floor` (each row's
/// ReLU floor in its byte) and with the top bits flipped (`x + 128`).
#[inline]
#[target_feature(enable = "avx512f,avx512bw")]
fn store_quads(words: &mut [u32; 16], rows: [__m512i; ROWS], floor: __m512i) {
    let word = _mm512_max_epi8(pack_quads(rows), floor);
    let word = _mm512_xor_si512(word, _mm512_set1_epi32(0x8080_8080_u32 as i32));
    // SAFETY: `words` is sixteen words (64 bytes); unaligned stores are
    // allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm512_storeu_si512(words.as_mut_ptr().cast(), word)
    };
}

/// Four rows' stepped accumulators of sixteen points (any i32 lanes) as
/// sixteen words, point `p`'s holding row `r`'s value in byte `r`, each
/// saturated to int8: the step's clamp but for its ReLU floor, which the
/// caller takes (`VPMAXSB`; the floor is -128 or above, so flooring after
/// the saturation is flooring before). `VPACKSSDW` then `VPACKSSWB`
/// saturate exactly as a clamp to [-128, 127] does and leave, in each
/// 128-bit block, four points' bytes row after row; one byte shuffle
/// turns that point after point.
#[inline]
#[target_feature(enable = "avx512f,avx512bw")]
fn pack_quads(rows: [__m512i; ROWS]) -> __m512i {
    let [r0, r1, r2, r3] = rows;
    let by_row = _mm512_packs_epi16(_mm512_packs_epi32(r0, r1), _mm512_packs_epi32(r2, r3));
    let by_point = _mm512_broadcast_i32x4(_mm_setr_epi8(
        0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15,
    ));
    _mm512_shuffle_epi8(by_row, by_point)
}

/// `OutputStep::apply` on sixteen accumulators but for the clamp (the
/// caller's, see [`pack_quads`]): on the fast path the high words of the
/// sixteen i64 products (`VPMULDQ` on the even lanes, then on the odd
/// lanes moved down), the folded offset and the arithmetic shift, the same
/// integer operations as the scalar step; lane by lane (clamped, which
/// changes nothing after) on the general one.
#[inline]
#[target_feature(enable = "avx512f")]
fn stepped(acc: __m512i, step: &OutputStep) -> __m512i {
    let Some((m, offset, high_shift, _)) = step.fast_parts() else {
        let mut lanes = [0i32; 16];
        // SAFETY: `lanes` is sixteen i32 (64 bytes); unaligned stores and
        // loads are allowed.
        #[allow(unsafe_code)]
        unsafe {
            _mm512_storeu_si512(lanes.as_mut_ptr().cast(), acc);
            let lanes = lanes.map(|a| step.apply(a) as i32);
            return _mm512_loadu_si512(lanes.as_ptr().cast());
        }
    };
    high_step(
        acc,
        _mm512_set1_epi32(m),
        _mm512_set1_epi32(offset),
        high_shift,
    )
}

/// The fast step of [`stepped`] (`m` and `offset` in every lane).
#[inline]
#[target_feature(enable = "avx512f")]
fn high_step(acc: __m512i, m: __m512i, offset: __m512i, high_shift: u32) -> __m512i {
    let even = _mm512_mul_epi32(acc, m);
    let odd = _mm512_mul_epi32(_mm512_srli_epi64::<32>(acc), m);
    // The even lanes take their product's high word (lane 2i + 1 of
    // `even`); the odd lanes already hold theirs.
    let hi = _mm512_mask_shuffle_epi32::<0xF5>(odd, 0x5555, even);
    _mm512_sra_epi32(
        _mm512_add_epi32(hi, offset),
        _mm_cvtsi32_si128(high_shift as i32),
    )
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::super::test_layer::block_cases;
    use super::super::tests::{check_layer, quads_by_point};
    use super::*;
    use std::vec::Vec;

    /// Whether this CPU can run the kernels (the tests say when it cannot).
    pub(in super::super) fn vnni() -> bool {
        let found = has_vnni();
        if !found {
            std::eprintln!("no AVX-512 VNNI on this CPU: the VNNI block kernels not tested");
        }
        found
    }

    /// The byte kernel gives the portable kernel's activations, stored and
    /// pooled, on every case of [`block_cases`]; what lies past a layer's
    /// inputs in its quads must not matter.
    #[test]
    fn byte_layer_matches_portable() {
        if !vnni() {
            return;
        }
        for c in block_cases(36) {
            let (q, inputs) = (c.layer.requant(), c.inputs);
            let sums: Vec<u32> = rows(&c.layer.weights, inputs)
                .map(super::super::area::row_sum)
                .collect();
            let layer = ByteLayer {
                weights: &c.layer.weights,
                inputs,
                sums: &sums,
            };
            let quads = quads_by_point(&c.x, inputs, 0x5A, 0x80);
            // SAFETY: the CPU has AVX-512 VNNI and BW (checked above).
            #[allow(unsafe_code)]
            check_layer(&c, "bytes", 0x80, &|out| {
                assert!(unsafe { layer_bytes(&layer, q, &quads, out) }, "buffers")
            });
        }
    }
}
