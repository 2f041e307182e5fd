//! The block kernel's AVX2 layer on int16 pairs (`VPMADDWD`): the first
//! layer, and every later one that does not run on bytes, when the CPU has
//! no AVX-512 VNNI.

use core::arch::x86_64::{
    __m256i, _mm256_add_epi32, _mm256_and_si256, _mm256_loadu_si256, _mm256_madd_epi16,
    _mm256_max_epi32, _mm256_or_si256, _mm256_set1_epi32, _mm256_slli_epi32, _mm256_storeu_si256,
};

use super::super::x86::{VectorStep, max};
use super::super::{Requant, rows, rows_mut};
#[cfg(test)]
use super::widen;
use super::{BLOCK, raise};
use crate::fixed::OutputStep;
use crate::format::le_i32s;

/// Vectors of eight points in a block.
pub(super) const VECTORS: usize = BLOCK / 8;

/// Where a layer's results go.
pub(super) enum Dest<'a> {
    /// The next layer's input pairs.
    Pairs(&'a mut [u32]),
    /// The running maxima of the pooled layer's accumulators ([`raise`]).
    Maxima(&'a mut [u32]),
}

/// One layer on a block: `weights` holds `outputs` rows of `pairs` words,
/// `input` the block's input pairs (`pairs x BLOCK` words).
#[target_feature(enable = "avx2")]
pub(super) fn layer(weights: &[u32], pairs: usize, q: Requant<'_>, input: &[u32], dest: Dest<'_>) {
    let Some(input) = input.get(..pairs * BLOCK) else {
        return;
    };
    let mut params = le_i32s(q.bias)
        .zip(le_i32s(q.multiplier))
        .zip(q.shift)
        .map(|((b, m), &s)| (b, OutputStep::new(m, s as i8, q.zero_point, q.act_min)));
    let mut channels = rows(weights, pairs);
    let (mut out, mut pool) = match dest {
        Dest::Pairs(output) => (Some(rows_mut(output, BLOCK)), None),
        Dest::Maxima(maxima) => (None, Some(maxima)),
    };
    let mut o = 0;
    while let (Some(r0), Some((b0, s0))) = (channels.next(), params.next()) {
        let second = channels.next().zip(params.next());
        let (r1, b1) = second.as_ref().map_or((r0, 0), |&(r, (b, _))| (r, b));
        // The rows' output steps, made ready once for the block's vectors.
        let k0 = VectorStep::new(&s0);
        let k1 = second.as_ref().map(|(_, (_, s))| VectorStep::new(s));
        let mut out = out.as_mut().and_then(|rows| rows.next());
        let (mut m0, mut m1) = (i32::MIN, i32::MIN);
        // Two rows share each load: half a block at a time keeps the
        // sixteen vectors of work in registers.
        for half in 0..2 {
            let mut acc0 = [_mm256_set1_epi32(b0); HALF];
            let mut acc1 = [_mm256_set1_epi32(b1); HALF];
            for ((&w0, &w1), x) in r0.iter().zip(r1).zip(rows(input, BLOCK)) {
                let (w0, w1) = (_mm256_set1_epi32(w0 as i32), _mm256_set1_epi32(w1 as i32));
                let x = half_of(x, half);
                for ((a0, a1), x) in acc0.iter_mut().zip(&mut acc1).zip(x.as_chunks::<8>().0) {
                    // SAFETY: `x` is eight words (32 bytes); unaligned
                    // loads are allowed.
                    #[allow(unsafe_code)]
                    let x = unsafe { _mm256_loadu_si256(x.as_ptr().cast::<__m256i>()) };
                    *a0 = _mm256_add_epi32(*a0, _mm256_madd_epi16(x, w0));
                    *a1 = _mm256_add_epi32(*a1, _mm256_madd_epi16(x, w1));
                }
            }
            if pool.is_some() {
                m0 = m0.max(largest(acc0));
                m1 = m1.max(largest(acc1));
                continue;
            }
            let Some(out) = out
                .as_deref_mut()
                .and_then(|out| out.get_mut(half * HALF * 8..))
            else {
                continue;
            };
            for ((a0, a1), out) in acc0.into_iter().zip(acc1).zip(out.as_chunks_mut::<8>().0) {
                let lo = k0.apply(a0);
                let hi = match &k1 {
                    Some(k) => k.apply(a1),
                    None => _mm256_set1_epi32(0),
                };
                let words = _mm256_or_si256(
                    _mm256_and_si256(lo, _mm256_set1_epi32(0xFFFF)),
                    _mm256_slli_epi32::<16>(hi),
                );
                // SAFETY: `out` is eight words (32 bytes); unaligned
                // stores are allowed.
                #[allow(unsafe_code)]
                unsafe {
                    _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), words)
                };
            }
        }
        if let Some(maxima) = &mut pool {
            raise(maxima, o, m0);
            if second.is_some() {
                raise(maxima, o + 1, m1);
            }
        }
        o += 2;
    }
}

/// Vectors of eight points in half a block.
pub(super) const HALF: usize = VECTORS / 2;

/// Half a block's words of one input (pair or quad).
pub(super) type Half = [u32; HALF * 8];

/// Half `half` of an input's words in a block (zeros if `x` is short).
#[inline(always)]
pub(super) fn half_of(x: &[u32], half: usize) -> &Half {
    x.get(half * HALF * 8..)
        .and_then(|x| x.first_chunk())
        .unwrap_or(&[0; HALF * 8])
}

/// The largest lane of the block's accumulators.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn largest<const N: usize>(acc: [__m256i; N]) -> i32 {
    let first = acc.first().copied().unwrap_or(_mm256_set1_epi32(i32::MIN));
    max(acc.into_iter().fold(first, |m, v| _mm256_max_epi32(m, v)))
}

#[cfg(test)]
mod tests {
    use super::super::super::test_layer::{TestLayer, byte};
    use super::super::super::{Sink, dense_tile};
    use super::super::pool_maxima;
    use super::super::tests::pairs_by_point;
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// One layer of the block kernel gives the portable kernel's
    /// activations, stored and max-pooled, on even and odd widths, on the
    /// fast and the general requantization paths.
    #[test]
    fn block_layer_matches_portable() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = SplitMix64(21);
        for &(inputs, outputs) in &[(2, 3), (16, 8), (33, 64), (64, 7), (128, 256), (7, 1)] {
            for shift_range in [(-22, -2), (-31, 31)] {
                let random = TestLayer::new(&mut rng, inputs, outputs, shift_range);
                let (weights, q) = (&random.weights, random.requant());
                let x: Vec<i8> = (0..BLOCK * inputs).map(|_| byte(&mut rng)).collect();
                let pairs = inputs.div_ceil(2);
                let mut wide = std::vec![0u32; outputs * pairs];
                widen(weights, inputs, &mut wide);
                let input = pairs_by_point(&x, inputs);
                let mut want = std::vec![0i8; BLOCK * outputs];
                let sink = &mut Sink::Store {
                    out: &mut want,
                    outputs,
                };
                dense_tile(weights, inputs, q, &x, sink);
                let mut out = std::vec![0u32; outputs.div_ceil(2) * BLOCK];
                // SAFETY: the CPU has AVX2 (checked above).
                #[allow(unsafe_code)]
                unsafe {
                    layer(&wide, pairs, q, &input, Dest::Pairs(&mut out))
                };
                let got: Vec<i8> = (0..BLOCK * outputs)
                    .map(|i| {
                        let (p, o) = (i / outputs, i % outputs);
                        (out[o / 2 * BLOCK + p] >> (16 * (o % 2))) as i16 as i8
                    })
                    .collect();
                assert_eq!(got, want, "stored, {inputs} -> {outputs}");
                let (mut want, mut got) =
                    (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
                dense_tile(weights, inputs, q, &x, &mut Sink::Pool(&mut want));
                let mut maxima = std::vec![i32::MIN as u32; outputs];
                // SAFETY: as above.
                #[allow(unsafe_code)]
                unsafe {
                    layer(&wide, pairs, q, &input, Dest::Maxima(&mut maxima))
                };
                pool_maxima(&maxima, q, &mut got);
                assert_eq!(got, want, "pooled, {inputs} -> {outputs}");
            }
        }
    }
}
