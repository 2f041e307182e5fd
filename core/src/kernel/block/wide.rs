//! The block kernel's int16-pair layers with AVX-512 VNNI (`VPDPWSSD`):
//! every layer that [`super::layer`] runs, when the CPU has it.

use core::arch::x86_64::{
    __m256i, __m512i, _mm256_and_si256, _mm256_or_si256, _mm256_set1_epi32, _mm256_setzero_si256,
    _mm256_slli_epi32, _mm256_storeu_si256, _mm512_castsi512_si256, _mm512_dpwssd_epi32,
    _mm512_extracti64x4_epi64, _mm512_set1_epi32, _mm512_setzero_si512,
};

use super::super::x86::activations;
use super::super::{Requant, Sink, rows, rows_mut};
use super::vnni::{ROWS, WIDE, block_vectors, largest_wide};
use super::{BLOCK, Dest};
use crate::fixed::OutputStep;

/// [`super::layer`] with AVX-512 VNNI: `weights` holds `outputs` rows of
/// `pairs` int16-pair words, `input` the block's input pairs by point.
/// `VPDPWSSD` multiplies each point's input pair with a broadcast weight
/// pair and adds both products to the point's i32 accumulator in one
/// instruction (no saturation), sixteen points a vector, three vectors a
/// block, four rows sharing each load. The activations go into the next
/// layer's pairs or the max-pool as in [`super::layer`], and the sums are
/// the same exact integers, so the results are its bits.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) fn layer_wide(
    weights: &[u32],
    pairs: usize,
    q: Requant<'_>,
    input: &[u32],
    dest: Dest<'_>,
) {
    let Some(input) = input.get(..pairs * BLOCK) else {
        return;
    };
    let outputs = q.bias.len() / 4;
    let (bias, mult) = (q.bias.as_chunks::<4>().0, q.multiplier.as_chunks::<4>().0);
    let (mut out, mut pool) = match dest {
        Dest::Pairs(output) => (Some(rows_mut(output, BLOCK)), None),
        Dest::Pool(feature) => (None, Some(Sink::Pool(feature))),
    };
    // Channels by index (see `pool_vnni`).
    for o in (0..outputs).step_by(ROWS) {
        let n = (outputs - o).min(ROWS);
        // Missing rows repeat the last with a zero bias; never taken.
        let mut rs = [&[][..]; ROWS];
        let mut acc = [[_mm512_setzero_si512(); WIDE]; ROWS];
        let mut steps = [None; ROWS];
        for (r, ((row, acc), step)) in rs.iter_mut().zip(&mut acc).zip(&mut steps).enumerate() {
            let ch = o + r.min(n - 1);
            *row = weights.get(ch * pairs..(ch + 1) * pairs).unwrap_or(&[]);
            if let (true, Some(&b), Some(&m), Some(&s)) =
                (r < n, bias.get(ch), mult.get(ch), q.shift.get(ch))
            {
                *acc = [_mm512_set1_epi32(i32::from_le_bytes(b)); WIDE];
                let m = i32::from_le_bytes(m);
                *step = Some(OutputStep::new(m, s as i8, q.zero_point, q.act_min));
            }
        }
        // (Plain loops: a closure would not inherit the target features,
        // and its intrinsics would become calls.)
        let [r0, r1, r2, r3] = rs;
        let columns = r0.iter().zip(r1).zip(r2).zip(r3);
        for ((((&a, &b), &c), &d), x) in columns.zip(rows(input, BLOCK)) {
            pair_step(&mut acc, [a, b, c, d], x);
        }
        if let Some(sink) = &mut pool {
            for (r, (acc, step)) in acc.iter().zip(&steps).enumerate() {
                if let Some(step) = step {
                    sink.take(o + r, 0, &[largest_wide(acc)], step);
                }
            }
        } else if let Some(out) = &mut out {
            for (a, b) in [(0, 1), (2, 3)] {
                if a >= n {
                    break;
                }
                if let Some(out) = out.next() {
                    pairs_out(acc[a], acc[b], steps[a].as_ref(), steps[b].as_ref(), out);
                }
            }
        }
    }
}

/// Adds to `ROWS` rows' accumulators over the block the products of their
/// weight pairs `w` with the input pairs `x` (one word per point).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
fn pair_step(acc: &mut [[__m512i; WIDE]; ROWS], w: [u32; ROWS], x: &[u32]) {
    let Some(xs) = block_vectors(x) else {
        return;
    };
    for (acc, &w) in acc.iter_mut().zip(&w) {
        let w = _mm512_set1_epi32(w as i32);
        for (a, &x) in acc.iter_mut().zip(&xs) {
            *a = _mm512_dpwssd_epi32(*a, x, w);
        }
    }
}

/// Two rows' activations over the block as int16 pairs by point (the first
/// row's in the low halves; zero for a missing row). Not inlined: taking
/// the accumulators by reference here would keep them in memory in the
/// loop.
#[inline(never)]
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
fn pairs_out(
    lo: [__m512i; WIDE],
    hi: [__m512i; WIDE],
    s0: Option<&OutputStep>,
    s1: Option<&OutputStep>,
    out: &mut [u32],
) {
    let (lo, hi) = (halves(lo), halves(hi));
    for ((lo, hi), out) in lo.into_iter().zip(hi).zip(out.as_chunks_mut::<8>().0) {
        let a = match s0 {
            Some(s) => activations(lo, s),
            None => _mm256_setzero_si256(),
        };
        let b = match s1 {
            Some(s) => activations(hi, s),
            None => _mm256_setzero_si256(),
        };
        let words = _mm256_or_si256(
            _mm256_and_si256(a, _mm256_set1_epi32(0xFFFF)),
            _mm256_slli_epi32::<16>(b),
        );
        // SAFETY: `out` is eight words (32 bytes); unaligned stores are
        // allowed.
        #[allow(unsafe_code)]
        unsafe {
            _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), words)
        };
    }
}

/// A row's accumulators as vectors of eight points.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
fn halves(v: [__m512i; WIDE]) -> [__m256i; 2 * WIDE] {
    let mut h = [_mm256_setzero_si256(); 2 * WIDE];
    for (h, v) in h.as_chunks_mut::<2>().0.iter_mut().zip(v) {
        *h = [_mm512_castsi512_si256(v), _mm512_extracti64x4_epi64::<1>(v)];
    }
    h
}

#[cfg(test)]
mod tests {
    use super::super::super::dense_tile;
    use super::super::super::test_layer::{TestLayer, byte};
    use super::super::tests::by_point;
    use super::super::vnni::has_vnni;
    use super::super::{layer, widen};
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// `layer_wide` gives the portable kernel's activations, stored and
    /// max-pooled, and the very pair words of the AVX2 `layer`, on even and
    /// odd widths (output counts that are and are not multiples of the four
    /// rows taken together), on both requantization paths.
    #[test]
    fn wide_layer_matches_portable_and_avx2() {
        if !has_vnni() {
            std::eprintln!("no AVX-512 VNNI on this CPU: layer_wide not tested");
            return;
        }
        let mut rng = SplitMix64(38);
        for &(inputs, outputs) in &[
            (4, 3),
            (3, 64),
            (16, 8),
            (33, 64),
            (64, 7),
            (128, 256),
            (7, 1),
            (9, 6),
        ] {
            for shifts in [(-22, -2), (-31, 31)] {
                let random = TestLayer::new(&mut rng, inputs, outputs, shifts);
                let (weights, q) = (&random.weights, random.requant());
                let x: Vec<i8> = (0..BLOCK * inputs).map(|_| byte(&mut rng)).collect();
                let pairs = inputs.div_ceil(2);
                let mut wide = std::vec![0u32; outputs * pairs];
                widen(weights, inputs, &mut wide);
                let input = by_point(&x, inputs);
                let mut want = std::vec![0i8; BLOCK * outputs];
                let sink = &mut Sink::Store {
                    out: &mut want,
                    outputs,
                };
                dense_tile(weights, inputs, q, &x, sink);
                let words = outputs.div_ceil(2) * BLOCK;
                let (mut got, mut avx2) = (std::vec![0u32; words], std::vec![0u32; words]);
                // SAFETY: the CPU has AVX-512 VNNI and BW (checked above),
                // and so AVX2.
                #[allow(unsafe_code)]
                unsafe {
                    layer_wide(&wide, pairs, q, &input, Dest::Pairs(&mut got));
                    layer(&wide, pairs, q, &input, Dest::Pairs(&mut avx2));
                }
                let stored: Vec<i8> = (0..BLOCK * outputs)
                    .map(|i| {
                        let (p, o) = (i / outputs, i % outputs);
                        (got[o / 2 * BLOCK + p] >> (16 * (o % 2))) as i16 as i8
                    })
                    .collect();
                assert_eq!(stored, want, "stored, {inputs} -> {outputs}");
                assert_eq!(got, avx2, "pair words, {inputs} -> {outputs}");
                let (mut want, mut got) =
                    (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
                dense_tile(weights, inputs, q, &x, &mut Sink::Pool(&mut want));
                // SAFETY: as above.
                #[allow(unsafe_code)]
                unsafe {
                    layer_wide(&wide, pairs, q, &input, Dest::Pool(&mut got))
                };
                assert_eq!(got, want, "pooled, {inputs} -> {outputs}");
            }
        }
    }
}
