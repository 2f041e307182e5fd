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
//! four rows takes 24 points at a time (three vectors of eight, twelve
//! accumulators, so that each `VPDPBUSD` has others to run while its
//! five-cycle latency passes; eight left the chains waiting) and the
//! block's last sixteen in a short pass; each row's weight quad is
//! broadcast from memory. The steps are `asm!` blocks (see
//! [`step_long`]). The output step is the AVX2 kernel's without its clamp
//! ([`high_step`]), then two saturating packs, one byte shuffle and the
//! ReLU floor put the four rows' bytes in point order, as on the AVX-512
//! route; the max-pool keeps a vector of running maxima per row over the
//! passes and reduces the four rows' at once ([`raise_group`]).
//!
//! The sums are the portable kernel's exact integers (products and pair
//! sums fit in i32, and model loading bounds every partial sum, see
//! [`super::super::dot`]), so the results are its bits.

use core::arch::asm;
use core::arch::x86_64::{
    __m256i, _mm_max_epi32, _mm_storeu_si128, _mm256_castsi256_si128, _mm256_extracti128_si256,
    _mm256_max_epi8, _mm256_max_epi32, _mm256_packs_epi16, _mm256_packs_epi32, _mm256_set1_epi32,
    _mm256_setr_epi8, _mm256_setzero_si256, _mm256_shuffle_epi8, _mm256_storeu_si256,
    _mm256_unpackhi_epi32, _mm256_unpackhi_epi64, _mm256_unpacklo_epi32, _mm256_unpacklo_epi64,
    _mm256_xor_si256,
};

use super::super::Requant;
use super::super::x86::{high_step, load, store};
use super::{BLOCK, ByteLayer, Out, ROWS, group, quad, raise};
use crate::fixed::OutputStep;

/// Vectors of eight points in a long pass: twelve accumulators, three
/// input vectors and a broadcast weight fill the sixteen registers.
const LONG: usize = 3;

/// Long passes over a block; the rest of it takes one short pass of
/// [`SHORT`] vectors.
const LONGS: usize = BLOCK / (8 * LONG);

/// Vectors of eight points in the block's last, short pass.
const SHORT: usize = BLOCK % (8 * LONG) / 8;

// The passes cover the block: a long pass's points do not divide it and
// the rest is whole vectors.
const _: () = assert!(SHORT > 0 && BLOCK.is_multiple_of(8));

/// A group's accumulators over a pass of `P` vectors: rows by vectors of
/// eight points.
type Acc<const P: usize> = [[__m256i; P]; ROWS];

pub(super) use super::super::x86::has_avxvnni;

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
fn start<const P: usize>(biases: [i32; ROWS]) -> Acc<P> {
    let mut acc = [[_mm256_setzero_si256(); P]; ROWS];
    for (acc, b) in acc.iter_mut().zip(biases) {
        *acc = [_mm256_set1_epi32(b); P];
    }
    acc
}

/// Runs `pass` on the block's points, [`LONGS`] long passes then a short
/// one, each from its first point; `best` collects the max-pool's vectors.
/// (A macro: the two pass widths are two instances of the same body, each
/// inlined with the caller's target features.)
macro_rules! passes {
    ($pass:ident) => {{
        for l in 0..LONGS {
            $pass!(LONG, step_long, 8 * LONG * l);
        }
        $pass!(SHORT, step_short, 8 * LONG * LONGS);
    }};
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
        let [r0, r1, r2, r3] = rs.map(word_bytes);
        let mut best = [_mm256_set1_epi32(i32::MIN); ROWS];
        macro_rules! pass {
            ($p:expr, $step:ident, $at:expr) => {{
                let mut acc = start::<{ $p }>(biases);
                let columns = r0.iter().zip(r1).zip(r2).zip(r3);
                for ((((a, b), c), d), x) in columns.zip(input.as_chunks::<BLOCK>().0) {
                    $step(&mut acc, [a, b, c, d], x, $at, Product::Pairs);
                }
                finish(&acc, &steps, o, $at, &mut out, &mut best);
            }};
        }
        passes!(pass);
        if let Out::Maxima(maxima) = &mut out {
            raise_group(maxima, o, &steps, best);
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
        let mut best = [_mm256_set1_epi32(i32::MIN); ROWS];
        macro_rules! pass {
            ($p:expr, $step:ident, $at:expr) => {{
                let mut acc = start::<{ $p }>(biases);
                let words = r0.iter().zip(r1).zip(r2).zip(r3);
                for ((((a, b), c), d), x) in words.zip(quads) {
                    $step(&mut acc, [a, b, c, d], x, $at, Product::Bytes);
                }
                // The rows' last, partial quad.
                if let Some(x) = quads.get(full).filter(|_| full < count) {
                    let w = rs.map(|r| quad(r, full).to_le_bytes());
                    $step(&mut acc, w.each_ref(), x, $at, Product::Bytes);
                }
                finish(&acc, &steps, o, $at, &mut out, &mut best);
            }};
        }
        passes!(pass);
        if let Out::Maxima(maxima) = &mut out {
            raise_group(maxima, o, &steps, best);
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

/// Defines a pass step over `$p` vectors for one instruction `$op`: adds
/// to the rows' accumulators over the pass from point `at` the products
/// of their weight words `w` (broadcast) with the pass's input words in
/// `x`, one row of the block. One `asm!` block: in a long pass the twelve
/// accumulators, three input vectors and the broadcast weight take all
/// sixteen registers, and the compiler, given the same with intrinsics,
/// spilled an accumulator and copied others between registers on every
/// step. `x:` names the input vectors' registers with their byte offsets,
/// `rows:` each row's weight pointer and its accumulators, each with the
/// input vector it takes.
macro_rules! pass_step {
    ($name:ident, $op:literal, $p:literal,
     x: [$($xv:ident $off:literal),+],
     rows: [$($wr:ident [$($a:ident $xa:ident),+]),+]) => {
        #[inline]
        #[target_feature(enable = "avx2,avxvnni")]
        fn $name(acc: &mut Acc<$p>, w: [&[u8; 4]; ROWS], x: &[u32; BLOCK], at: usize) {
            let Some(x) = x.get(at..).and_then(|x| x.first_chunk::<{ 8 * $p }>()) else {
                return;
            };
            let [$([$($a),+]),+] = acc;
            let [$($wr),+] = w;
            // SAFETY: the CPU has AVX-VNNI and AVX2 (the caller's); the
            // block reads the `32 P` bytes of `x` from `at` and the four
            // bytes of each `w`, and writes only its register operands.
            #[allow(unsafe_code)]
            unsafe {
                asm!(
                    $(concat!("vmovdqu {", stringify!($xv), "}, ymmword ptr [{x}", $off, "]"),)+
                    $(
                        concat!("vpbroadcastd {w}, dword ptr [{", stringify!($wr), "}]"),
                        $(concat!(
                            "{{vex}} ", $op, " {", stringify!($a), "}, {", stringify!($xa), "}, {w}"
                        ),)+
                    )+
                    x = in(reg) x.as_ptr(),
                    $($wr = in(reg) $wr.as_ptr(),)+
                    $($($a = inout(ymm_reg) *$a,)+)+
                    $($xv = out(ymm_reg) _,)+
                    w = out(ymm_reg) _,
                    options(pure, readonly, nostack, preserves_flags),
                )
            }
        }
    };
}

/// [`pass_step`] on a long pass (three vectors).
macro_rules! long_step {
    ($name:ident, $op:literal) => {
        pass_step!($name, $op, 3,
            x: [x0 "", x1 " + 32", x2 " + 64"],
            rows: [
                w0 [a00 x0, a01 x1, a02 x2],
                w1 [a10 x0, a11 x1, a12 x2],
                w2 [a20 x0, a21 x1, a22 x2],
                w3 [a30 x0, a31 x1, a32 x2]
            ]);
    };
}

/// [`pass_step`] on the short pass (two vectors).
macro_rules! short_step {
    ($name:ident, $op:literal) => {
        pass_step!($name, $op, 2,
            x: [x0 "", x1 " + 32"],
            rows: [w0 [a00 x0, a01 x1], w1 [a10 x0, a11 x1], w2 [a20 x0, a21 x1], w3 [a30 x0, a31 x1]]);
    };
}

long_step!(long_pairs, "vpdpwssd");
long_step!(long_bytes, "vpdpbusd");
short_step!(short_pairs, "vpdpwssd");
short_step!(short_bytes, "vpdpbusd");

/// A long pass's step on `product` ([`pass_step`]).
#[inline]
#[target_feature(enable = "avx2,avxvnni")]
fn step_long(acc: &mut Acc<3>, w: [&[u8; 4]; ROWS], x: &[u32; BLOCK], at: usize, product: Product) {
    match product {
        Product::Pairs => long_pairs(acc, w, x, at),
        Product::Bytes => long_bytes(acc, w, x, at),
    }
}

/// The short pass's step on `product` ([`pass_step`]).
#[inline]
#[target_feature(enable = "avx2,avxvnni")]
fn step_short(
    acc: &mut Acc<2>,
    w: [&[u8; 4]; ROWS],
    x: &[u32; BLOCK],
    at: usize,
    product: Product,
) {
    match product {
        Product::Pairs => short_pairs(acc, w, x, at),
        Product::Bytes => short_bytes(acc, w, x, at),
    }
}

/// Words as their bytes.
fn word_bytes(words: &[u32]) -> &[[u8; 4]] {
    // SAFETY: `[u8; 4]` has the size of `u32`, alignment 1 and no invalid
    // bit patterns, so the same memory holds `words.len()` of them.
    #[allow(unsafe_code)]
    unsafe {
        core::slice::from_raw_parts(words.as_ptr().cast(), words.len())
    }
}

/// The end of a pass of a group of rows `o..o + ROWS`: each row's
/// accumulators raise its vector of running maxima in `best` when `out`
/// is the max-pool ([`raise_group`] takes them into it after the last
/// pass), or go through the row's step into the next layer's quads (word
/// `o / 4` of each point of the pass, plus 128).
#[inline(never)]
#[target_feature(enable = "avx2")]
fn finish<const P: usize>(
    acc: &Acc<P>,
    steps: &[Option<OutputStep>; ROWS],
    o: usize,
    at: usize,
    out: &mut Out<'_>,
    best: &mut [__m256i; ROWS],
) {
    match out {
        Out::Maxima(_) => {
            for (b, acc) in best.iter_mut().zip(acc) {
                for &a in acc {
                    *b = _mm256_max_epi32(*b, a);
                }
            }
        }
        Out::Quads(quads) => {
            let Some(words) = quads.get_mut(o / ROWS * BLOCK + at..) else {
                return;
            };
            // The ReLU floor in each row's byte of a word; a missing row's
            // byte stays 0 under -128.
            let floor = steps.map(|s| s.map_or(i8::MIN, |s| s.act_min()) as u8);
            let floor = _mm256_set1_epi32(i32::from_le_bytes(floor));
            let words = words.as_chunks_mut::<8>().0.iter_mut().take(P);
            let fast = steps.map(|s| s.and_then(|s| s.fast_parts()));
            if let [Some(f0), Some(f1), Some(f2), Some(f3)] = fast {
                // Every row on the fast path (the usual case): its constants
                // once for the pass, straight-line steps.
                let parts = [f0, f1, f2, f3];
                let mut m = [_mm256_setzero_si256(); ROWS];
                let mut offset = [_mm256_setzero_si256(); ROWS];
                for ((m, offset), &(mr, or, _, _)) in m.iter_mut().zip(&mut offset).zip(&parts) {
                    *m = _mm256_set1_epi32(mr);
                    *offset = _mm256_set1_epi32(or);
                }
                for (v, words) in words.enumerate() {
                    let mut rows = [_mm256_setzero_si256(); ROWS];
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
                    let mut rows = [_mm256_setzero_si256(); ROWS];
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

/// Four rows' stepped accumulators of eight points (any i32 lanes) as
/// the next layer's eight quad words: `VPACKSSDW` and `VPACKSSWB`
/// saturate as the step's clamp to 127 does, one byte shuffle puts the
/// bytes in point order, `floor` (each row's ReLU floor in its byte)
/// takes the clamp's other end (flooring after the saturation is flooring
/// before, as the floor is -128 or above), and the top bits flip (`x +
/// 128`).
#[inline]
#[target_feature(enable = "avx2")]
fn store_quads(words: &mut [u32; 8], rows: [__m256i; ROWS], floor: __m256i) {
    // In each 128-bit lane, byte `4p + r` from byte `4r + p`.
    let by_point = _mm256_setr_epi8(
        0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15, 0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10,
        14, 3, 7, 11, 15,
    );
    let [r0, r1, r2, r3] = rows;
    let by_row = _mm256_packs_epi16(_mm256_packs_epi32(r0, r1), _mm256_packs_epi32(r2, r3));
    let word = _mm256_max_epi8(_mm256_shuffle_epi8(by_row, by_point), floor);
    let word = _mm256_xor_si256(word, _mm256_set1_epi32(0x8080_8080_u32 as i32));
    // SAFETY: `words` is eight words (32 bytes); unaligned stores are
    // allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_si256(words.as_mut_ptr().cast(), word)
    };
}

/// Raises the running maxima of rows `o..o + ROWS` (those with a step)
/// to the largest lanes of their vectors in `best`: within each 128-bit
/// half, pairs of lanes, then pairs of pairs, leave lane `r` holding row
/// `r`'s largest; then across the halves.
#[inline]
#[target_feature(enable = "avx2")]
fn raise_group(
    maxima: &mut [u32],
    o: usize,
    steps: &[Option<OutputStep>; ROWS],
    best: [__m256i; ROWS],
) {
    let [m0, m1, m2, m3] = best;
    let t0 = _mm256_max_epi32(_mm256_unpacklo_epi32(m0, m1), _mm256_unpackhi_epi32(m0, m1));
    let t1 = _mm256_max_epi32(_mm256_unpacklo_epi32(m2, m3), _mm256_unpackhi_epi32(m2, m3));
    let u = _mm256_max_epi32(_mm256_unpacklo_epi64(t0, t1), _mm256_unpackhi_epi64(t0, t1));
    let w = _mm_max_epi32(_mm256_castsi256_si128(u), _mm256_extracti128_si256::<1>(u));
    let mut largest = [0i32; ROWS];
    // SAFETY: `largest` is four i32 (16 bytes); unaligned stores are
    // allowed.
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

/// `OutputStep::apply` on eight accumulators but for the clamp (which the
/// caller's packs and floor take): [`high_step`] on the fast path, lane by
/// lane (clamped, which changes nothing after) on the general one.
#[inline]
#[target_feature(enable = "avx2")]
fn stepped(acc: __m256i, step: &OutputStep) -> __m256i {
    match step.fast_parts() {
        Some((m, offset, high_shift, _)) => high_step(
            acc,
            _mm256_set1_epi32(m),
            _mm256_set1_epi32(offset),
            high_shift,
        ),
        None => load(store(acc).map(|a| step.apply(a) as i32)),
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
                .map(super::super::area::row_sum)
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
