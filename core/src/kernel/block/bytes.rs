//! The pooled (last) encoder layer of the block kernel on bytes
//! (`VPMADDUBSW`), when its input is an int8 activation.

use core::arch::x86_64::{
    __m256i, _mm256_add_epi16, _mm256_add_epi32, _mm256_and_si256, _mm256_loadu_si256,
    _mm256_madd_epi16, _mm256_maddubs_epi16, _mm256_or_si256, _mm256_set1_epi8, _mm256_set1_epi16,
    _mm256_set1_epi32, _mm256_setzero_si256, _mm256_slli_epi32, _mm256_srli_epi32,
    _mm256_storeu_si256, _mm256_testz_si256,
};

use super::super::{Requant, rows, rows_mut};
use super::pairs::{HALF, Half, VECTORS, half_of, largest};
use super::{BLOCK, ByteLayer, quad, raise};
use crate::format::le_i32s;

/// The pooled (last) layer, its input an int8 activation. `VPMADDUBSW`
/// multiplies 32 unsigned bytes by 32 signed ones (`VPMADDWD`: 16 int16
/// pairs) and saturates each sum of two products to int16. Here that sum
/// can never saturate:
///
/// - each input `x` is moved to `u = x + 128` (0..=255; the bias takes
///   `-128 * sum(w)`) and split into its low seven bits `l = u & 127` and
///   its top bit `h = u >> 7`, so `u = l + 128 h`;
/// - the low bits go through `VPMADDUBSW` against four weights at a time:
///   `|l1 w1 + l2 w2| <= 127 * 128 * 2 = 32512 < 32767`, for any int8
///   weights; `VPMADDWD` with ones adds the two int16 sums of a point into
///   its i32 lane;
/// - the high bits are 1 only where the activation is in the upper half of
///   its range, which after a ReLU is rare (in 3.4% of the quads of a
///   block at the pooled layer's input, on the ModelNet10 benchmark
///   clouds, measured with blocks of 48 points). Only the quads where
///   some point of the block has one take a second pass, `VPMADDUBSW` on
///   `h`, then `VPMADDWD` with 128.
///
/// Per 32 products that is still two multiply instructions, as in
/// [`super::layer`], but one `VPADDD` instead of two, half the loads of
/// inputs, and the int8 weights read as stored, not copied to int16 first.
/// On a Zen 3 the layer (128 -> 1024, a block of 48 points then) ran at
/// 28 multiply-adds a cycle against 23 for the int16 kernel.
///
/// A quad with a high bit costs a second pass as long as the first, so
/// when more than an eighth of the block's quads have one (inputs spread
/// over their whole range, as with random weights) the int16 kernel is
/// faster: this returns `false` having changed nothing but its scratch,
/// and the caller runs [`super::layer`] (on int16 weights it copies the
/// first time). The criterion bench's random paper-width model encodes
/// 1024 points in 2.39 ms with this rule, 2.52 ms on bytes throughout and
/// 2.35 ms on int16 throughout; the trained and calibrated models, whose
/// blocks all stay on bytes, are 7-10% faster than on int16.
///
/// `input` holds the block's input as int16 pairs by point (as
/// [`super::layer`]'s), `bytes` room for the two byte buffers, `quads` for
/// the list of quads with a high bit; each output's largest accumulator
/// raises its entry of `maxima` (see [`super::pool_maxima`]). The
/// accumulator of every point is the portable kernel's, so the pooled
/// feature is too.
#[target_feature(enable = "avx2")]
pub(super) fn pool_bytes(
    pooled: &ByteLayer<'_>,
    q: Requant<'_>,
    input: &[u32],
    bytes: &mut [u32],
    quads: &mut [u32],
    maxima: &mut [u32],
) -> bool {
    let count = pooled.inputs.div_ceil(4);
    let Some(input) = input.get(..pooled.inputs.div_ceil(2) * BLOCK) else {
        return false;
    };
    let (low, high) = bytes.split_at_mut(bytes.len().min(count * BLOCK));
    let hot = split_bytes(input, pooled.inputs, low, high, quads);
    if 8 * hot > count {
        return false;
    }
    let (Some(hot), Some(high)) = (quads.get(..hot), high.get(..hot * BLOCK)) else {
        return false;
    };
    let biases = le_i32s(q.bias)
        .zip(pooled.sums)
        .map(|(b, &sum)| b.wrapping_sub((sum as i32).wrapping_mul(128)));
    let ones = _mm256_set1_epi16(1);
    let top = _mm256_set1_epi16(128);
    let mut channels = rows(pooled.weights, pooled.inputs).zip(biases);
    let mut o = 0;
    while let Some((r0, b0)) = channels.next() {
        let second = channels.next();
        let (r1, b1) = second.unwrap_or((r0, 0));
        let (f0, f1) = (r0.as_chunks::<4>().0, r1.as_chunks::<4>().0);
        let (mut m0, mut m1) = (i32::MIN, i32::MIN);
        // Two rows share each load: half a block at a time keeps the
        // sixteen vectors of work in registers.
        for half in 0..2 {
            let mut acc0 = [_mm256_set1_epi32(b0); HALF];
            let mut acc1 = [_mm256_set1_epi32(b1); HALF];
            for (x, (&a, &b)) in rows(low, BLOCK).zip(f0.iter().zip(f1)) {
                let w = (i32::from_le_bytes(a), i32::from_le_bytes(b));
                quad_step(&mut acc0, &mut acc1, w, half_of(x, half), ones);
            }
            // The rows' last, partial quad.
            if let Some(x) = rows(low, BLOCK).nth(f0.len()) {
                let w = (quad(r0, f0.len()), quad(r1, f0.len()));
                quad_step(&mut acc0, &mut acc1, w, half_of(x, half), ones);
            }
            for (&j, x) in hot.iter().zip(rows(high, BLOCK)) {
                let w = (quad(r0, j as usize), quad(r1, j as usize));
                quad_step(&mut acc0, &mut acc1, w, half_of(x, half), top);
            }
            m0 = m0.max(largest(acc0));
            m1 = m1.max(largest(acc1));
        }
        raise(maxima, o, m0);
        if second.is_some() {
            raise(maxima, o + 1, m1);
        }
        o += 2;
    }
    true
}

/// Adds to two rows' accumulators over half a block the products of their
/// weight quads `w` with the byte quads `x`, each point's four products
/// summed and times `scale` (int16 lanes).
#[inline]
#[target_feature(enable = "avx2")]
fn quad_step(
    acc0: &mut [__m256i; HALF],
    acc1: &mut [__m256i; HALF],
    w: (i32, i32),
    x: &Half,
    scale: __m256i,
) {
    let (w0, w1) = (_mm256_set1_epi32(w.0), _mm256_set1_epi32(w.1));
    for ((a0, a1), x) in acc0.iter_mut().zip(acc1).zip(x.as_chunks::<8>().0) {
        // SAFETY: `x` is eight words (32 bytes); unaligned loads are
        // allowed.
        #[allow(unsafe_code)]
        let x = unsafe { _mm256_loadu_si256(x.as_ptr().cast::<__m256i>()) };
        let p0 = _mm256_madd_epi16(_mm256_maddubs_epi16(x, w0), scale);
        let p1 = _mm256_madd_epi16(_mm256_maddubs_epi16(x, w1), scale);
        *a0 = _mm256_add_epi32(*a0, p0);
        *a1 = _mm256_add_epi32(*a1, p1);
    }
}

/// Eight points' int16 pair `(x0, x1)` (zeros for `None`) as the bytes
/// `x0 + 128` and `x1 + 128` in the low half of each point's word.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn bytes_of(pairs: Option<&[u32; 8]>) -> __m256i {
    let Some(pairs) = pairs else {
        return _mm256_setzero_si256();
    };
    // SAFETY: `pairs` is eight words (32 bytes); unaligned loads are
    // allowed.
    #[allow(unsafe_code)]
    let w = unsafe { _mm256_loadu_si256(pairs.as_ptr().cast::<__m256i>()) };
    // Each int16 plus 128 is 0..=255; the high one's byte then goes next to
    // the low one's.
    let u = _mm256_add_epi16(w, _mm256_set1_epi16(128));
    _mm256_and_si256(
        _mm256_or_si256(u, _mm256_srli_epi32::<8>(u)),
        _mm256_set1_epi32(0xFFFF),
    )
}

/// Splits the block's int16 input pairs into byte quads by point (word `j *
/// BLOCK + p` holds point `p`'s inputs `4j..4j + 4`, zero past `inputs`):
/// the low seven bits of `x + 128` into `low`, and, for the quads where
/// some point has its top bit, the top bits into `high`, in order, their
/// quad numbers into `quads`. Returns how many such quads there are.
#[target_feature(enable = "avx2")]
fn split_bytes(
    input: &[u32],
    inputs: usize,
    low: &mut [u32],
    high: &mut [u32],
    quads: &mut [u32],
) -> usize {
    let pairs = rows(input, BLOCK);
    let mut pairs = pairs.map(Some).chain(core::iter::repeat(None));
    let mut hot = 0;
    for (j, low) in rows_mut(low, BLOCK).enumerate() {
        let (Some(a), b) = (pairs.next().flatten(), pairs.next().flatten()) else {
            break;
        };
        // Inputs past the end are zero bytes (their weights are zero too,
        // see `quad`), so a padding pair's `x = 0` never marks a quad.
        let valid = inputs.saturating_sub(4 * j).min(4) as u32;
        let mask = u64::MAX.checked_shr(64 - 8 * valid).unwrap_or(0);
        let mask = _mm256_set1_epi32(mask as u32 as i32);
        let mut any = _mm256_setzero_si256();
        let mut tops = [_mm256_setzero_si256(); VECTORS];
        let a = a.as_chunks::<8>().0;
        let b = b.map(|b| b.as_chunks::<8>().0);
        for (v, (low, top)) in low
            .as_chunks_mut::<8>()
            .0
            .iter_mut()
            .zip(&mut tops)
            .enumerate()
        {
            let lo = bytes_of(a.get(v));
            let hi = bytes_of(b.and_then(|b| b.get(v)));
            let u = _mm256_and_si256(_mm256_or_si256(lo, _mm256_slli_epi32::<16>(hi)), mask);
            let l = _mm256_and_si256(u, _mm256_set1_epi8(0x7F));
            *top = _mm256_and_si256(_mm256_srli_epi32::<7>(u), _mm256_set1_epi8(1));
            any = _mm256_or_si256(any, *top);
            // SAFETY: `low` is eight words (32 bytes); unaligned stores
            // are allowed.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_si256(low.as_mut_ptr().cast::<__m256i>(), l)
            };
        }
        if _mm256_testz_si256(any, any) != 0 {
            continue;
        }
        let (Some(slot), Some(out)) = (quads.get_mut(hot), high.get_mut(hot * BLOCK..)) else {
            break;
        };
        *slot = j as u32;
        for (out, top) in out.as_chunks_mut::<8>().0.iter_mut().zip(tops) {
            // SAFETY: `out` is eight words (32 bytes); unaligned stores
            // are allowed.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), top)
            };
        }
        hot += 1;
    }
    hot
}

#[cfg(test)]
mod tests {
    use super::super::super::Sink;
    use super::super::super::test_layer::{TestLayer, byte};
    use super::super::pool_maxima;
    use super::super::tests::pairs_by_point;
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// The pooled feature of `pool_bytes` against the portable kernel's,
    /// or, when more than an eighth of the quads have an input in the upper
    /// half, that it declines. Returns whether it took the block.
    fn check(layer: &TestLayer, inputs: usize, outputs: usize, x: &[i8], what: &str) -> bool {
        let q = layer.requant();
        let sums: Vec<u32> = rows(&layer.weights, inputs)
            .map(super::super::area::row_sum)
            .collect();
        let pooled = ByteLayer {
            weights: &layer.weights,
            inputs,
            sums: &sums,
        };
        let count = inputs.div_ceil(4);
        let (mut bytes, mut lists) = (
            std::vec![0u32; 2 * count * BLOCK],
            std::vec![0u32; 2 * count],
        );
        let (mut want, mut got) = (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
        let mut maxima = std::vec![i32::MIN as u32; outputs];
        let sink = &mut Sink::Pool(&mut want);
        super::super::super::dense_tile(&layer.weights, inputs, q, x, sink);
        // SAFETY: the caller checked for AVX2.
        #[allow(unsafe_code)]
        let took = unsafe {
            pool_bytes(
                &pooled,
                q,
                &pairs_by_point(x, inputs),
                &mut bytes,
                &mut lists,
                &mut maxima,
            )
        };
        pool_maxima(&maxima, q, &mut got);
        let hot = (0..count)
            .filter(|&j| {
                let quad = |row: &[i8]| row.iter().skip(4 * j).take(4).any(|&v| v >= 0);
                x.chunks(inputs).any(quad)
            })
            .count();
        assert_eq!(took, 8 * hot <= count, "{what}: {hot} of {count} quads hot");
        if took {
            assert_eq!(got, want, "{what}, {inputs} -> {outputs}");
        }
        took
    }

    /// Random layers of widths that are and are not multiples of four,
    /// odd and even output counts, both requantization paths; inputs over
    /// the whole int8 range (nearly every quad has a high bit: declined),
    /// in its lower half only (none has) and in the lower half but for a
    /// few inputs (some have).
    #[test]
    fn pooled_bytes_match_portable() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = SplitMix64(34);
        let shapes = [
            (1, 1),
            (5, 3),
            (8, 8),
            (33, 17),
            (64, 64),
            (128, 256),
            (130, 5),
        ];
        for &(inputs, outputs) in &shapes {
            for shifts in [(-22, -2), (-31, 31)] {
                let layer = TestLayer::new(&mut rng, inputs, outputs, shifts);
                let n = BLOCK * inputs;
                let whole: Vec<i8> = (0..n).map(|_| byte(&mut rng)).collect();
                assert!(!check(&layer, inputs, outputs, &whole, "whole range"));
                let low: Vec<i8> = (0..n).map(|_| rng.int(-128, -1) as i8).collect();
                assert!(check(&layer, inputs, outputs, &low, "lower half"));
                // Every 48th input (the first of every twelfth quad) in the
                // upper half for one point in eight.
                let few: Vec<i8> = (0..n)
                    .map(|i| match (i % inputs % 48, rng.int(0, 7)) {
                        (0, 0) => rng.int(0, 127) as i8,
                        _ => rng.int(-128, -1) as i8,
                    })
                    .collect();
                let took = check(&layer, inputs, outputs, &few, "a few in the upper half");
                assert!(took || inputs < 64, "a few, {inputs} inputs");
                let quarter: Vec<i8> = (0..n).map(|_| rng.int(-128, -65) as i8).collect();
                assert!(check(&layer, inputs, outputs, &quarter, "lowest quarter"));
                // Inputs in the lowest quarter or the lower half, by input.
                let limits: Vec<i32> = (0..inputs)
                    .map(|_| [-65, -1][rng.int(0, 1) as usize])
                    .collect();
                let mixed: Vec<i8> = (0..n)
                    .map(|i| rng.int(-128, limits[i % inputs]) as i8)
                    .collect();
                assert!(check(&layer, inputs, outputs, &mixed, "quarters by input"));
            }
        }
    }

    /// The largest sums of two products `VPMADDUBSW` can meet: every
    /// weight -128 or 127, every input at the top of the low seven bits
    /// (`x = -1`, `u = 127`), at 63 (`x = -65`), at the bottom, or the
    /// first quad's inputs at the top of the range (`x = 127`, low bits
    /// 127 and a high bit) and the others at `x = -1`. The bias brings the true accumulator to 400 and the
    /// output step divides by 8, so the activation is 50, far from either
    /// clamp: an accumulator off by more than 4 would show.
    #[test]
    fn pooled_bytes_extremes_do_not_saturate() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = SplitMix64(35);
        let (inputs, outputs) = (128, 4);
        for weight in [-128i8, 127] {
            // The first quad's inputs, then every other input.
            for (first, rest) in [(-1i8, -1i8), (-65, -65), (-128, -128), (127, -1)] {
                let mut layer = TestLayer::new(&mut rng, inputs, outputs, (-2, -2));
                layer.weights.fill(weight as u8);
                let dot = weight as i32 * (4 * first as i32 + (inputs as i32 - 4) * rest as i32);
                layer.bias = (0..outputs)
                    .flat_map(|_| (400 - dot).to_le_bytes())
                    .collect();
                layer.multiplier = (0..outputs)
                    .flat_map(|_| (1i32 << 30).to_le_bytes())
                    .collect();
                layer.zero_point = 0;
                let x: Vec<i8> = (0..BLOCK * inputs)
                    .map(|i| if i % inputs < 4 { first } else { rest })
                    .collect();
                let mut want = std::vec![i8::MIN; outputs];
                let q = layer.requant();
                super::super::super::dense_tile(
                    &layer.weights,
                    inputs,
                    q,
                    &x,
                    &mut Sink::Pool(&mut want),
                );
                assert_eq!(
                    want,
                    std::vec![50; outputs],
                    "the portable kernel's activation"
                );
                assert!(check(&layer, inputs, outputs, &x, "extreme"));
            }
        }
    }
}
