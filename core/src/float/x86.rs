//! The f32 encoder's x86-64 AVX kernel, chosen at run time (`std` feature),
//! its tile's inner products with AVX-512F where the CPU has it.
//!
//! [`F32_TILE`] points go through the layers together, one point per
//! vector lane: the tile's activations are stored input-major (`x[i][t]`),
//! and each output's sum is `bias`, then `+ w[i] * x[i]` for `i` in
//! ascending order, a separate IEEE-754 multiply and add per lane (no
//! fused multiply-add), then ReLU. That is the portable path's sequence of
//! operations for every point, so every point gets the same bits; the
//! max-pool compares the points in source order, as the portable path
//! does, so signed zeros and the first of equal values come out the same.
//!
//! Dense layers on one vector (the head, and [`super::dense`] wherever it
//! is called) run eight outputs at a time, one output per lane: each
//! lane's sum still runs over the inputs in ascending order, one multiply
//! and one add at a time, so again every output gets the portable bits;
//! the eight sums are independent, which hides the adder's latency that
//! bounds the one-output loop.

use core::arch::x86_64::{
    __m256, _CMP_LT_OQ, _mm256_add_ps, _mm256_andnot_ps, _mm256_cmp_ps, _mm256_cvtss_f32,
    _mm256_loadu_ps, _mm256_max_ps, _mm256_mul_ps, _mm256_permute2f128_ps, _mm256_set1_ps,
    _mm256_setzero_ps, _mm256_shuffle_ps, _mm256_storeu_ps, _mm256_unpackhi_ps, _mm256_unpacklo_ps,
    _mm512_add_ps, _mm512_cmp_ps_mask, _mm512_loadu_ps, _mm512_maskz_mov_ps, _mm512_mul_ps,
    _mm512_set1_ps, _mm512_setzero_ps, _mm512_storeu_ps,
};

use super::{Layer, Params, pool};
use crate::arch::{Arch, F32_TILE, INPUT_DIM, ping_pong, prefix};
use crate::error::{Error, Result};
use crate::pose::PointMap;
use crate::registration::Sample;

/// Lanes of one AVX vector.
const LANES: usize = 8;

/// Encodes `sample` (each point moved by `map`) into `feature` as the
/// portable path does, [`F32_TILE`] points at a time. Returns `Ok(false)`,
/// having done nothing, without AVX or when `work` cannot hold two tiles
/// of the widest hidden layer.
pub(super) fn encode<P: Params>(
    layers: &[Layer<P>],
    arch: &Arch,
    sample: Sample<'_>,
    map: &PointMap,
    feature: &mut [f32],
    work: &mut [f32],
) -> Result<bool> {
    let half = F32_TILE * arch.widest_hidden_encoder();
    if work.len() < 2 * half || !std::is_x86_feature_detected!("avx") {
        return Ok(false);
    }
    let (a, b) = ping_pong(work, half)?;
    // SAFETY: the CPU has AVX (checked above), all `tiles` and `outputs`
    // require, and AVX-512F where `outputs_wide` is picked.
    #[allow(unsafe_code)]
    unsafe {
        if std::is_x86_feature_detected!("avx512f") {
            tiles(layers, arch, sample, map, feature, a, b, outputs_wide::<P>)?
        } else {
            tiles(layers, arch, sample, map, feature, a, b, outputs::<P>)?
        }
    };
    Ok(true)
}

/// A kernel for `B` outputs over a tile ([`outputs`], [`outputs_wide`]).
type Block<P, const B: usize> = unsafe fn([P; B], [f32; B], &[f32]) -> [[f32; F32_TILE]; B];

/// The encoder over the sample, a tile at a time, `B` outputs at a time
/// through `block`, which the caller's CPU must support.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx")]
fn tiles<'w, P: Params, const B: usize>(
    layers: &[Layer<P>],
    arch: &Arch,
    sample: Sample<'_>,
    map: &PointMap,
    feature: &mut [f32],
    mut a: &'w mut [f32],
    mut b: &'w mut [f32],
    block: Block<P, B>,
) -> Result<()> {
    let last = layers.len().saturating_sub(1);
    let mut points = sample.iter().peekable();
    while points.peek().is_some() {
        // The tile's points, input-major; lanes past the sample's end
        // repeat its first point and are never pooled.
        let mut x0 = [[0f32; F32_TILE]; INPUT_DIM];
        let mut filled = 0;
        for (t, (index, p)) in points.by_ref().take(F32_TILE).enumerate() {
            if p.iter().any(|x| !x.is_finite()) {
                return Err(Error::NonFiniteCoordinate { index });
            }
            for (x, v) in x0.iter_mut().zip(map.apply(*p)) {
                if let Some(lane) = x.get_mut(t) {
                    *lane = v;
                }
            }
            filled = t + 1;
        }
        for x in &mut x0 {
            let first = x[0];
            x.iter_mut().skip(filled).for_each(|v| *v = first);
        }
        let mut inputs = INPUT_DIM;
        for (l, (layer, shape)) in layers.iter().zip(arch.encoder_layers()).enumerate() {
            let x = if l == 0 {
                x0.as_flattened()
            } else {
                prefix(a, inputs * F32_TILE)?
            };
            let out = b.as_chunks_mut::<F32_TILE>().0.iter_mut();
            let mut out = out.take(if l == last { 0 } else { shape.outputs });
            // `B` outputs at a time: eight independent sums in flight. The
            // last block repeats its last output where there are fewer than
            // `B` left; the repeats are dropped.
            for o in (0..shape.outputs).step_by(B) {
                // Loops, not `array::from_fn`: its closure is not inlined.
                let mut rows = [layer.weights.slice(o * inputs, inputs); B];
                let mut bias = [layer.bias.get(o); B];
                for (j, (row, bias)) in rows.iter_mut().zip(&mut bias).enumerate() {
                    let k = (o + j).min(shape.outputs - 1);
                    *row = layer.weights.slice(k * inputs, inputs);
                    *bias = layer.bias.get(k);
                }
                // SAFETY: the caller checked the CPU for `block`.
                #[allow(unsafe_code)]
                let values = unsafe { block(rows, bias, x) };
                // No closure here: `pool_tile` would not be inlined in one.
                for (j, v) in values.iter().enumerate().take(shape.outputs - o) {
                    if l != last {
                        if let Some(y) = out.next() {
                            *y = *v;
                        }
                    } else if let Some(f) = feature.get_mut(o + j) {
                        pool_tile(f, v, filled);
                    }
                }
            }
            if l != last {
                core::mem::swap(&mut a, &mut b);
            }
            inputs = shape.outputs;
        }
    }
    Ok(())
}

/// The portable path's max-pool over the tile's first `n` points, point
/// by point in order ([`pool`]), with its bits: the tile's largest value
/// is found with `VMAXPS` first and decides alone where that is the same
/// thing. [`pool`] keeps `f` unless a point is larger, takes no NaN, and
/// of equal values keeps the first, which only shows for zeros (`-0.0 ==
/// 0.0`): every other value has one bit pattern. So with the largest
/// non-NaN value `m` of `f` and the points, `f` stays when `m <= f`,
/// becomes `m` when `m > f` and `m != 0`, and only a tile whose largest
/// value is a zero above `f` (a channel the ReLU zeroed for the whole
/// tile) goes through [`pool`] point by point, to keep the first zero's
/// sign. Lanes past `n` repeat the first point's value (see [`tiles`]),
/// which changes no maximum.
#[inline]
#[target_feature(enable = "avx")]
fn pool_tile(f: &mut f32, v: &[f32; F32_TILE], n: usize) {
    let [lo, hi] = v.as_chunks::<LANES>().0 else {
        return;
    };
    // `VMAXPS a, b` gives `b` when either is NaN: the points go first, so
    // a NaN point leaves the running maximum (never NaN: `f` is not).
    let m = _mm256_max_ps(load(*hi), _mm256_max_ps(load(*lo), _mm256_set1_ps(*f)));
    let m = _mm256_max_ps(m, _mm256_permute2f128_ps::<0x01>(m, m));
    let m = _mm256_max_ps(m, _mm256_shuffle_ps::<0b01_00_11_10>(m, m));
    let m = _mm256_max_ps(m, _mm256_shuffle_ps::<0b10_11_00_01>(m, m));
    let m = _mm256_cvtss_f32(m);
    if m <= *f {
        return;
    }
    if m != 0.0 {
        *f = m;
        return;
    }
    for &v in v.iter().take(n) {
        pool(f, v);
    }
}

/// Outputs per pass of the tiled encoder.
const BLOCK: usize = 4;

/// Four outputs over the tile: `relu(bias + sum_i w[i] * x[i])`, the sum
/// in ascending `i`, for the tile's points (`x` input-major; `rows` the
/// outputs' weight rows).
#[target_feature(enable = "avx")]
fn outputs<P: Params>(rows: [P; BLOCK], bias: [f32; BLOCK], x: &[f32]) -> [[f32; F32_TILE]; BLOCK] {
    let mut acc = bias.map(|b| [_mm256_set1_ps(b); F32_TILE / LANES]);
    // One zip over the inputs: a single trip count, no per-row end checks.
    let [w0, w1, w2, w3] = rows;
    let inputs = x.as_chunks::<F32_TILE>().0.iter();
    let columns = inputs.zip(
        w0.values()
            .zip(w1.values())
            .zip(w2.values())
            .zip(w3.values()),
    );
    for (xi, (((w0, w1), w2), w3)) in columns {
        let [lo, hi] = xi.as_chunks::<LANES>().0 else {
            continue;
        };
        // SAFETY: `lo` and `hi` are 8 f32 each; unaligned loads are allowed.
        #[allow(unsafe_code)]
        let (lo, hi) = unsafe { (_mm256_loadu_ps(lo.as_ptr()), _mm256_loadu_ps(hi.as_ptr())) };
        for (acc, w) in acc.iter_mut().zip([w0, w1, w2, w3]) {
            let w = _mm256_set1_ps(w);
            let [a_lo, a_hi] = acc;
            *a_lo = _mm256_add_ps(*a_lo, _mm256_mul_ps(w, lo));
            *a_hi = _mm256_add_ps(*a_hi, _mm256_mul_ps(w, hi));
        }
    }
    // A loop, not `acc.map`: a closure has no AVX of its own, so its
    // intrinsics would not be inlined.
    let mut out = [[0f32; F32_TILE]; BLOCK];
    for (acc, out) in acc.iter().zip(&mut out) {
        for (acc, lanes) in acc.iter().zip(out.as_chunks_mut::<LANES>().0) {
            // ReLU as the portable path: 0.0 where the sum is below zero,
            // the sum itself otherwise (-0.0 and NaN pass unchanged).
            let below: __m256 = _mm256_cmp_ps::<_CMP_LT_OQ>(*acc, _mm256_setzero_ps());
            // SAFETY: `lanes` is 8 f32; unaligned stores are allowed.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_ps(lanes.as_mut_ptr(), _mm256_andnot_ps(below, *acc))
            };
        }
    }
    out
}

/// Outputs per pass of the AVX-512 kernel: eight, one vector of the
/// tile's sixteen points each, again eight sums in flight.
const WIDE_BLOCK: usize = 8;

/// [`outputs`] with AVX-512F, eight outputs at a time, the tile's sixteen
/// points in one vector: the same multiply, then add, per lane and input
/// in the same order, so the same bits.
#[target_feature(enable = "avx512f")]
fn outputs_wide<P: Params>(
    rows: [P; WIDE_BLOCK],
    bias: [f32; WIDE_BLOCK],
    x: &[f32],
) -> [[f32; F32_TILE]; WIDE_BLOCK] {
    let mut acc = [_mm512_setzero_ps(); WIDE_BLOCK];
    for (acc, &b) in acc.iter_mut().zip(&bias) {
        *acc = _mm512_set1_ps(b);
    }
    // One zip over the inputs: a single trip count, no per-row end checks.
    let [w0, w1, w2, w3, w4, w5, w6, w7] = rows;
    let inputs = x.as_chunks::<F32_TILE>().0.iter();
    let columns = inputs.zip(
        w0.values()
            .zip(w1.values())
            .zip(w2.values())
            .zip(w3.values())
            .zip(w4.values())
            .zip(w5.values())
            .zip(w6.values())
            .zip(w7.values()),
    );
    for (xi, (((((((w0, w1), w2), w3), w4), w5), w6), w7)) in columns {
        // SAFETY: `xi` is 16 f32; unaligned loads are allowed.
        #[allow(unsafe_code)]
        let xi = unsafe { _mm512_loadu_ps(xi.as_ptr()) };
        for (acc, w) in acc.iter_mut().zip([w0, w1, w2, w3, w4, w5, w6, w7]) {
            *acc = _mm512_add_ps(*acc, _mm512_mul_ps(_mm512_set1_ps(w), xi));
        }
    }
    let mut out = [[0f32; F32_TILE]; WIDE_BLOCK];
    for (acc, out) in acc.iter().zip(&mut out) {
        // ReLU as the portable path (see `outputs`).
        let below = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(*acc, _mm512_setzero_ps());
        let relu = _mm512_maskz_mov_ps(!below, *acc);
        // SAFETY: `out` is 16 f32; unaligned stores are allowed.
        #[allow(unsafe_code)]
        unsafe {
            _mm512_storeu_ps(out.as_mut_ptr(), relu)
        };
    }
    out
}

/// [`super::dense_concat`] for the first `outputs / 8 * 8` outputs, eight
/// at a time, each passed to `emit`; returns how many outputs were done
/// (0 without AVX).
pub(super) fn dense_concat<P: Params, A: Params>(
    layer: &Layer<P>,
    a: A,
    x: &[f32],
    outputs: usize,
    relu: bool,
    emit: &mut impl FnMut(usize, f32),
) -> usize {
    if outputs < LANES || !std::is_x86_feature_detected!("avx") {
        return 0;
    }
    // SAFETY: the CPU has AVX (checked above), all `rows8` requires.
    #[allow(unsafe_code)]
    unsafe {
        rows8(layer, a, x, outputs, relu, emit)
    }
}

#[target_feature(enable = "avx")]
fn rows8<P: Params, A: Params>(
    layer: &Layer<P>,
    a: A,
    x: &[f32],
    outputs: usize,
    relu: bool,
    emit: &mut impl FnMut(usize, f32),
) -> usize {
    let inputs = a.len() + x.len();
    let blocks = outputs / LANES;
    for block in 0..blocks {
        let o0 = block * LANES;
        let rows: [P; LANES] =
            core::array::from_fn(|r| layer.weights.slice((o0 + r) * inputs, inputs));
        let mut acc = load(core::array::from_fn(|r| layer.bias.get(o0 + r)));
        acc = accumulate(acc, &rows, 0, a);
        acc = accumulate(acc, &rows, a.len(), x);
        if relu {
            acc = _mm256_andnot_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(acc, _mm256_setzero_ps()), acc);
        }
        for (r, v) in store(acc).into_iter().enumerate() {
            emit(o0 + r, v);
        }
    }
    blocks * LANES
}

/// `acc[r] + sum_i rows[r][offset + i] * input[i]` for the eight rows, `i`
/// ascending: eight inputs at a time through an 8 x 8 transpose of the
/// rows' weights (columns: one input's weights of the eight rows), then
/// one input at a time.
#[target_feature(enable = "avx")]
#[inline]
fn accumulate<P: Params, I: Params>(
    mut acc: __m256,
    rows: &[P; LANES],
    offset: usize,
    input: I,
) -> __m256 {
    // Plain loops, no closures: a closure has no AVX of its own, so the
    // helpers called from it would not be inlined and every vector would
    // go through memory.
    let full = input.len() / LANES;
    for c in 0..full {
        let at = offset + c * LANES;
        let mut block = [_mm256_setzero_ps(); LANES];
        for (b, r) in block.iter_mut().zip(rows) {
            *b = load(r.slice(at, LANES).first8());
        }
        let xs = input.slice(c * LANES, LANES).first8();
        for (w, x) in transpose(block).into_iter().zip(xs) {
            acc = _mm256_add_ps(acc, _mm256_mul_ps(w, _mm256_set1_ps(x)));
        }
    }
    for i in full * LANES..input.len() {
        let mut w = [0f32; LANES];
        for (v, r) in w.iter_mut().zip(rows) {
            *v = r.get(offset + i);
        }
        acc = _mm256_add_ps(acc, _mm256_mul_ps(load(w), _mm256_set1_ps(input.get(i))));
    }
    acc
}

/// The 8 x 8 transpose: `out[j]` lane `r` is `rows[r]` lane `j`.
#[target_feature(enable = "avx")]
#[inline]
fn transpose(rows: [__m256; LANES]) -> [__m256; LANES] {
    let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
    let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
    let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
    let (t4, t5) = (_mm256_unpacklo_ps(r4, r5), _mm256_unpackhi_ps(r4, r5));
    let (t6, t7) = (_mm256_unpacklo_ps(r6, r7), _mm256_unpackhi_ps(r6, r7));
    // Per 128-bit half: columns j and j + 4 of rows 0-3 (s0-s3), 4-7 (s4-s7).
    let s0 = _mm256_shuffle_ps::<0x44>(t0, t2);
    let s1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
    let s2 = _mm256_shuffle_ps::<0x44>(t1, t3);
    let s3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
    let s4 = _mm256_shuffle_ps::<0x44>(t4, t6);
    let s5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
    let s6 = _mm256_shuffle_ps::<0x44>(t5, t7);
    let s7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
    [
        _mm256_permute2f128_ps::<0x20>(s0, s4),
        _mm256_permute2f128_ps::<0x20>(s1, s5),
        _mm256_permute2f128_ps::<0x20>(s2, s6),
        _mm256_permute2f128_ps::<0x20>(s3, s7),
        _mm256_permute2f128_ps::<0x31>(s0, s4),
        _mm256_permute2f128_ps::<0x31>(s1, s5),
        _mm256_permute2f128_ps::<0x31>(s2, s6),
        _mm256_permute2f128_ps::<0x31>(s3, s7),
    ]
}

#[target_feature(enable = "avx")]
#[inline]
fn load(values: [f32; LANES]) -> __m256 {
    // SAFETY: `values` is 8 f32; unaligned loads are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_loadu_ps(values.as_ptr())
    }
}

#[target_feature(enable = "avx")]
#[inline]
fn store(v: __m256) -> [f32; LANES] {
    let mut out = [0f32; LANES];
    // SAFETY: `out` is 8 f32; unaligned stores are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_ps(out.as_mut_ptr(), v)
    };
    out
}

#[cfg(test)]
mod tests;
