//! The pooled (last) encoder layer of the block kernel with AVX-512 VNNI
//! (`VPDPBUSD`), when its input is an int8 activation and the CPU has it.

use core::arch::x86_64::{
    __m512i, _mm256_and_si256, _mm256_or_si256, _mm256_set1_epi32, _mm256_slli_epi32,
    _mm256_storeu_si256, _mm512_dpbusd_epi32, _mm512_loadu_si512, _mm512_max_epi32,
    _mm512_reduce_max_epi32, _mm512_set1_epi32, _mm512_setzero_si512,
};

use super::super::{Requant, Sink, rows, rows_mut};
use super::bytes::{Pooled, bytes_of, quad};
use super::{BLOCK, VECTORS};
use crate::fixed::OutputStep;

/// Rows that share each load of the block's inputs (here and in
/// [`super::wide`]).
pub(super) const ROWS: usize = 4;

/// Vectors of sixteen points in a block.
pub(super) const WIDE: usize = BLOCK / 16;

/// Whether the CPU has what the AVX-512 VNNI kernels need (VNNI and BW,
/// which imply F).
pub(super) fn has_vnni() -> bool {
    std::is_x86_feature_detected!("avx512vnni") && std::is_x86_feature_detected!("avx512bw")
}

/// The pooled (last) layer, its input an int8 activation, on a CPU with
/// AVX-512 VNNI. `VPDPBUSD` multiplies 64 unsigned bytes by 64 signed ones
/// and adds each lane's four products to its i32 accumulator, with no
/// intermediate saturation, so no input needs splitting as in
/// [`super::bytes::pool_bytes`]:
///
/// - each input `x` is moved to `u = x + 128` (0..=255) and the bias takes
///   `-128 * sum(w)`, so `b + sum(w x) = b - 128 sum(w) + sum(w u)`;
/// - the inputs are laid out as byte quads by point (word `j * BLOCK + p`
///   holds point `p`'s inputs `4j..4j + 4`, zero past `inputs`, where the
///   weights are zero too), three vectors of sixteen points per quad;
/// - four rows at a time share each load: each row's weight quad is
///   broadcast and `VPDPBUSD` adds 64 products into sixteen points' lanes,
///   twelve accumulators in all; the largest of a row's 48 accumulators
///   goes to the max-pool.
///
/// Each lane's four products are at most `4 * 255 * 128` in magnitude,
/// and the accumulator is the portable kernel's (its sums wrap in i32 the
/// same way and model loading bounds them), so the pooled feature is too.
///
/// `input` holds the block's input as int16 pairs by point (as
/// [`super::layer`]'s), `bytes` room for the byte quads. Returns `false`,
/// having written nothing, when a buffer is short.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) fn pool_vnni(
    pooled: &Pooled<'_>,
    q: Requant<'_>,
    input: &[u32],
    bytes: &mut [u32],
    feature: &mut [i8],
) -> bool {
    let count = pooled.inputs.div_ceil(4);
    let (Some(input), Some(bytes)) = (
        input.get(..pooled.inputs.div_ceil(2) * BLOCK),
        bytes.get_mut(..count * BLOCK),
    ) else {
        return false;
    };
    quads_of(input, pooled.inputs, bytes);
    let bytes = &*bytes;
    let (inputs, full) = (pooled.inputs, pooled.inputs / 4);
    let outputs = pooled.sums.len();
    let mut sink = Sink::Pool(feature);
    // Channels by index, not by a chain of iterators: per group of rows
    // that chain cost as much as a sixth of the layer's time.
    let (bias, mult) = (q.bias.as_chunks::<4>().0, q.multiplier.as_chunks::<4>().0);
    for o in (0..outputs).step_by(ROWS) {
        let n = (outputs - o).min(ROWS);
        // Missing rows repeat the last with a zero bias; never taken.
        let mut rs = [&[][..]; ROWS];
        let mut bs = [0i32; ROWS];
        for (r, (row, b)) in rs.iter_mut().zip(&mut bs).enumerate() {
            let ch = o + r.min(n - 1);
            *row = pooled
                .weights
                .get(ch * inputs..(ch + 1) * inputs)
                .unwrap_or(&[]);
            if r < n {
                let b0 = bias.get(ch).copied().unwrap_or_default();
                let sum = pooled.sums.get(ch).copied().unwrap_or_default();
                *b = i32::from_le_bytes(b0).wrapping_sub((sum as i32).wrapping_mul(128));
            }
        }
        let [r0, r1, r2, r3] = rs;
        let mut acc = [[_mm512_setzero_si512(); WIDE]; ROWS];
        for (acc, &b) in acc.iter_mut().zip(&bs) {
            *acc = [_mm512_set1_epi32(b); WIDE];
        }
        // (Plain loops: a closure would not inherit the target features,
        // and its intrinsics would become calls.)
        let quads = r0.as_chunks::<4>().0.iter();
        let quads = quads.zip(r1.as_chunks::<4>().0);
        let quads = quads.zip(r2.as_chunks::<4>().0);
        let quads = quads.zip(r3.as_chunks::<4>().0);
        let mut x = rows(bytes, BLOCK);
        for (((&a, &b), &c), &d) in quads {
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
        for (r, acc) in acc.iter().enumerate().take(n) {
            let ch = o + r;
            let (Some(&m), Some(&s)) = (mult.get(ch), q.shift.get(ch)) else {
                break;
            };
            let step = OutputStep::new(i32::from_le_bytes(m), s as i8, q.zero_point, q.act_min);
            sink.take(ch, 0, &[largest_wide(acc)], &step);
        }
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
    // SAFETY: `x` is `BLOCK` = 16 * WIDE words, 64 bytes from each word
    // `16 v`; unaligned loads are allowed.
    #[allow(unsafe_code)]
    let xs = unsafe {
        [
            _mm512_loadu_si512(x.as_ptr().cast()),
            _mm512_loadu_si512(x[16..].as_ptr().cast()),
            _mm512_loadu_si512(x[32..].as_ptr().cast()),
        ]
    };
    Some(xs)
}

/// The largest lane of a row's accumulators over the block.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) fn largest_wide(acc: &[__m512i; WIDE]) -> i32 {
    _mm512_reduce_max_epi32(_mm512_max_epi32(_mm512_max_epi32(acc[0], acc[1]), acc[2]))
}

/// The block's int16 input pairs as byte quads of `x + 128` by point (word
/// `j * BLOCK + p` holds point `p`'s inputs `4j..4j + 4`, zero past
/// `inputs`).
#[target_feature(enable = "avx2")]
fn quads_of(input: &[u32], inputs: usize, out: &mut [u32]) {
    let mut pairs = rows(input, BLOCK).map(Some).chain(core::iter::repeat(None));
    for (j, out) in rows_mut(out, BLOCK).enumerate() {
        let (a, b) = (pairs.next().flatten(), pairs.next().flatten());
        let valid = inputs.saturating_sub(4 * j).min(4) as u32;
        let mask = u64::MAX.checked_shr(64 - 8 * valid).unwrap_or(0);
        let mask = _mm256_set1_epi32(mask as u32 as i32);
        let a = a.map(|a| a.as_chunks::<8>().0);
        let b = b.map(|b| b.as_chunks::<8>().0);
        for (v, out) in out
            .as_chunks_mut::<8>()
            .0
            .iter_mut()
            .enumerate()
            .take(VECTORS)
        {
            let lo = bytes_of(a.and_then(|a| a.get(v)));
            let hi = bytes_of(b.and_then(|b| b.get(v)));
            let u = _mm256_and_si256(_mm256_or_si256(lo, _mm256_slli_epi32::<16>(hi)), mask);
            // SAFETY: `out` is eight words (32 bytes); unaligned stores are
            // allowed.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_si256(out.as_mut_ptr().cast(), u)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::dense_tile;
    use super::super::super::test_layer::{TestLayer, byte};
    use super::super::tests::by_point;
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// Whether this CPU can run the kernel (the tests say when it cannot).
    fn vnni() -> bool {
        let found = has_vnni();
        if !found {
            std::eprintln!("no AVX-512 VNNI on this CPU: pool_vnni not tested");
        }
        found
    }

    /// The pooled feature of `pool_vnni` against the portable kernel's.
    fn check(layer: &TestLayer, inputs: usize, outputs: usize, x: &[i8], what: &str) {
        let q = layer.requant();
        let sums: Vec<u32> = rows(&layer.weights, inputs)
            .map(|r| r.iter().map(|&w| w as i8 as i32).sum::<i32>() as u32)
            .collect();
        let pooled = Pooled {
            weights: &layer.weights,
            inputs,
            sums: &sums,
        };
        let mut bytes = std::vec![0u32; inputs.div_ceil(4) * BLOCK];
        let (mut want, mut got) = (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
        dense_tile(&layer.weights, inputs, q, x, &mut Sink::Pool(&mut want));
        // SAFETY: the caller checked for AVX-512 VNNI and BW.
        #[allow(unsafe_code)]
        let done = unsafe { pool_vnni(&pooled, q, &by_point(x, inputs), &mut bytes, &mut got) };
        assert!(done, "{what}: buffers");
        assert_eq!(got, want, "{what}, {inputs} -> {outputs}");
    }

    /// Random layers of widths that are and are not multiples of four,
    /// output counts that are and are not multiples of the four rows taken
    /// together, both requantization paths; inputs over the whole int8
    /// range, in its lower or upper half only, and at either end.
    #[test]
    fn pooled_vnni_matches_portable() {
        if !vnni() {
            return;
        }
        let mut rng = SplitMix64(36);
        let shapes = [
            (1, 1),
            (5, 3),
            (8, 8),
            (33, 17),
            (64, 64),
            (128, 256),
            (130, 5),
            (7, 10),
        ];
        for &(inputs, outputs) in &shapes {
            for shifts in [(-22, -2), (-31, 31)] {
                let layer = TestLayer::new(&mut rng, inputs, outputs, shifts);
                let n = BLOCK * inputs;
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
                for (what, x) in &patterns {
                    check(&layer, inputs, outputs, x, what);
                }
            }
        }
    }

    /// The largest products `VPDPBUSD` meets: every weight -128 or 127,
    /// every input -128, -1 or 127. The bias brings the true accumulator to
    /// 400 and the output step divides by 8, so the activation is 50, far
    /// from either clamp: an accumulator off by more than 4 would show.
    #[test]
    fn pooled_vnni_extremes() {
        if !vnni() {
            return;
        }
        let mut rng = SplitMix64(37);
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
                let x = std::vec![x; BLOCK * inputs];
                let mut want = std::vec![i8::MIN; outputs];
                dense_tile(
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
                check(&layer, inputs, outputs, &x, "extreme");
            }
        }
    }
}
