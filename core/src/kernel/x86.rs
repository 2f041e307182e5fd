//! The x86-64 AVX2 encoder kernels, chosen at run time (`std` feature).
//!
//! The first layer (three int16 coordinates): per output, three
//! `VPMULLD` over a full tile's eight points. The other layers, on a full
//! tile of [`ROWS`] points: the tile's int8 activations are copied
//! to int16 once, then for every output channel the weight row is read 16
//! bytes at a time, sign-extended to int16 (`VPMOVSXBW`) and multiplied
//! with each point's 16 activations by `VPMADDWD` (16 MACs, pairs summed
//! into eight i32 lanes). Each point keeps its own vector of partial sums;
//! a horizontal-add tree turns the eight vectors into the eight dot
//! products. Inputs past the last multiple of 16 are added by the scalar
//! loop. Both then add the bias and apply the output step to the eight
//! sums at once (or the max-pool to their largest).
//!
//! Every product and pair sum fits in i32 (|w|, |x| <= 128), and model
//! loading bounds every partial sum (see [`super::dot`]): the result is the
//! portable kernel's, bit for bit, whatever the order.

use core::arch::x86_64::{
    __m128i, __m256i, _mm_loadu_si128, _mm256_add_epi32, _mm256_cvtepi8_epi16, _mm256_hadd_epi32,
    _mm256_loadu_si256, _mm256_madd_epi16, _mm256_mullo_epi32, _mm256_permute2x128_si256,
    _mm256_set1_epi32, _mm256_setzero_si256,
};

use super::{OutputStep, Requant, Sink, row_groups, rows, scalar_dot};

mod lanes;
mod vnni;
use crate::format::le_i32s;
pub(super) use lanes::{VectorStep, activations, high_step, load, max, store};
pub(super) use vnni::{has_avxvnni, has_vnni};

/// Points per tile of this kernel (the int8 path's largest tile).
const ROWS: usize = crate::arch::MAX_TILE;

/// Inputs per `VPMADDWD`.
const LANES: usize = 16;

/// [`super::dense_tile`]'s contract and results for a full tile of
/// [`ROWS`] points with at least 16 inputs, on a CPU with AVX2. Returns
/// `false`, having done nothing, on any other tile or CPU, or when
/// `expanded` cannot hold the tile's int16 copy.
pub(super) fn dense_tile(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[i8],
    expanded: &mut [u32],
    sink: &mut Sink<'_>,
) -> bool {
    if inputs < LANES || x.len() != ROWS * inputs || !std::is_x86_feature_detected!("avx2") {
        return false;
    }
    let Some(xs) = as_i16(expanded).get_mut(..ROWS * inputs) else {
        return false;
    };
    // SAFETY: the CPU has AVX2 (checked above), which is all `tile`
    // requires of its caller.
    #[allow(unsafe_code)]
    unsafe {
        tile(weights, inputs, q, x, xs, sink)
    };
    true
}

/// The words of `expanded` as int16 values.
pub(super) fn as_i16(words: &mut [u32]) -> &mut [i16] {
    // SAFETY: u32's alignment is a multiple of i16's and every bit pattern
    // is a valid i16; `align_to_mut` hands out the aligned middle only
    // (here all of it), with `words`' lifetime.
    #[allow(unsafe_code)]
    let (_, halves, _) = unsafe { words.align_to_mut::<i16>() };
    halves
}

#[target_feature(enable = "avx2")]
fn tile(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[i8],
    xs: &mut [i16],
    sink: &mut Sink<'_>,
) {
    for (d, &s) in xs.iter_mut().zip(x) {
        *d = s as i16;
    }
    let full = inputs / LANES * LANES;
    let mut points = rows(&*xs, inputs);
    let points: [&[i16]; ROWS] = core::array::from_fn(|_| points.next().unwrap_or(&[]));
    let mut tails = rows(x, inputs);
    let tails: [&[i8]; ROWS] =
        core::array::from_fn(|_| tails.next().map_or(&[][..], |r| r.split_at(full).1));
    outputs(weights, inputs, q, sink, |row| {
        let (body, tail) = row.split_at(full);
        let mut acc = [_mm256_setzero_si256(); ROWS];
        for (c, w) in body.chunks_exact(LANES).enumerate() {
            // SAFETY: `w` is 16 bytes long, and every point's row holds
            // `inputs >= full` values, so 16 values from `c * 16 < full`
            // are in bounds; unaligned loads are allowed.
            #[allow(unsafe_code)]
            unsafe {
                let w = _mm256_cvtepi8_epi16(_mm_loadu_si128(w.as_ptr().cast::<__m128i>()));
                for (acc, p) in acc.iter_mut().zip(points) {
                    let xv = _mm256_loadu_si256(p.as_ptr().add(c * LANES).cast::<__m256i>());
                    *acc = _mm256_add_epi32(*acc, _mm256_madd_epi16(w, xv));
                }
            }
        }
        let sum = reduce(acc);
        if tail.is_empty() {
            sum
        } else {
            _mm256_add_epi32(sum, load(tails.map(|t| scalar_dot(tail, t))))
        }
    });
}

/// [`super::dense_points`]' contract and results for a full tile of
/// [`ROWS`] points (`points`: their int16 `x y z`) on a CPU with AVX2:
/// per output, three `VPMULLD` over the eight points. Returns `false`,
/// having done nothing, on any other tile or CPU.
pub(super) fn dense_points(
    weights: &[u8],
    q: Requant<'_>,
    points: &[i16],
    sink: &mut Sink<'_>,
) -> bool {
    let Ok(points) = <&[i16; 3 * ROWS]>::try_from(points) else {
        return false;
    };
    if !std::is_x86_feature_detected!("avx2") {
        return false;
    }
    // SAFETY: the CPU has AVX2 (checked above), all `points8` requires.
    #[allow(unsafe_code)]
    unsafe {
        points8(weights, q, points, sink)
    };
    true
}

#[target_feature(enable = "avx2")]
fn points8(weights: &[u8], q: Requant<'_>, points: &[i16; 3 * ROWS], sink: &mut Sink<'_>) {
    // The coordinates, one vector per axis.
    let axes: [__m256i; 3] = core::array::from_fn(|k| {
        load(core::array::from_fn(|t| {
            points.as_chunks::<3>().0.get(t).map_or(0, |p| p[k] as i32)
        }))
    });
    outputs(weights, 3, q, sink, |row| {
        // |w| <= 128, |coordinate| <= 32767: no product or sum overflows.
        let mut sum = _mm256_setzero_si256();
        for (&w, axis) in row.iter().zip(axes) {
            let w = _mm256_set1_epi32(w as i8 as i32);
            sum = _mm256_add_epi32(sum, _mm256_mullo_epi32(w, axis));
        }
        sum
    });
}

/// [`super::dense_vector`]'s contract and results for a vector of at
/// least 16 inputs (the concatenation of `parts`) on a CPU with AVX2: with
/// AVX-512 VNNI [`vnni::vector`], with AVX-VNNI [`vnni::vector_avx`];
/// otherwise the vector is copied to int16
/// once, then each weight row is read 16 bytes at a time, sign-extended
/// (`VPMOVSXBW`) and multiplied with the vector by `VPMADDWD`, four rows at
/// once; lane sums, the scalar tail past the last multiple of 16, the bias
/// and the output step follow. Returns `false`, having done nothing, on any
/// other vector or CPU, or when `expanded` cannot hold the int16 copy.
pub(super) fn dense_vector(
    weights: &[u8],
    skip: usize,
    parts: &[&[u8]],
    q: Requant<'_>,
    expanded: &mut [u32],
    out: &mut [i8],
) -> bool {
    let inputs: usize = parts.iter().map(|p| p.len()).sum();
    if inputs < LANES || !std::is_x86_feature_detected!("avx2") {
        return false;
    }
    if vnni::has_vnni() {
        // SAFETY: the CPU has AVX-512 VNNI and BW (which imply F), all
        // `vnni::vector` requires.
        #[allow(unsafe_code)]
        unsafe {
            vnni::vector(weights, skip, parts, q, out)
        };
        return true;
    }
    if has_avxvnni() {
        // SAFETY: the CPU has AVX-VNNI and AVX2, all `vnni::vector_avx`
        // requires.
        #[allow(unsafe_code)]
        unsafe {
            vnni::vector_avx(weights, skip, parts, q, out)
        };
        return true;
    }
    dense_vector_avx2(weights, skip, parts, inputs, q, expanded, out)
}

/// [`dense_vector`] on AVX2 alone (which the caller found), for `inputs`
/// (at least 16) in all.
fn dense_vector_avx2(
    weights: &[u8],
    skip: usize,
    parts: &[&[u8]],
    inputs: usize,
    q: Requant<'_>,
    expanded: &mut [u32],
    out: &mut [i8],
) -> bool {
    let Some(xs) = as_i16(expanded).get_mut(..inputs) else {
        return false;
    };
    for (d, &s) in xs.iter_mut().zip(parts.iter().flat_map(|p| p.iter())) {
        *d = s as i8 as i16;
    }
    // SAFETY: the CPU has AVX2 (checked above), all `vector` requires.
    #[allow(unsafe_code)]
    unsafe {
        vector(weights, skip, inputs, q, xs, out)
    };
    true
}

#[target_feature(enable = "avx2")]
fn vector(weights: &[u8], skip: usize, inputs: usize, q: Requant<'_>, xs: &[i16], out: &mut [i8]) {
    let full = inputs / LANES * LANES;
    let (body, tail) = xs.split_at(full.min(xs.len()));
    for (rs, channels) in row_groups(weights, skip, inputs, q, out) {
        let mut acc = [_mm256_setzero_si256(); ROWS];
        for (c, x) in body.chunks_exact(LANES).enumerate() {
            // SAFETY: `x` is 16 values (32 bytes) and every row holds
            // `inputs >= full` bytes, so 16 from `c * 16 < full` are in
            // bounds; unaligned loads are allowed.
            #[allow(unsafe_code)]
            unsafe {
                let x = _mm256_loadu_si256(x.as_ptr().cast::<__m256i>());
                for (acc, r) in acc.iter_mut().zip(rs) {
                    let w = _mm_loadu_si128(r.as_ptr().add(c * LANES).cast::<__m128i>());
                    *acc = _mm256_add_epi32(*acc, _mm256_madd_epi16(_mm256_cvtepi8_epi16(w), x));
                }
            }
        }
        let sums = store(reduce(acc));
        for ((channel, row), sum) in channels.into_iter().zip(rs).zip(sums) {
            let Some((bias, step, y)) = channel else {
                continue;
            };
            let rest = row.get(full..).unwrap_or(&[]).iter().zip(tail);
            let rest = rest.fold(0i32, |a, (&w, &x)| {
                a.wrapping_add(w as i8 as i32 * x as i32)
            });
            *y = step.apply(bias.wrapping_add(sum).wrapping_add(rest));
        }
    }
}

/// For every output channel `o` (weight row `row`): `sum(row)` gives the
/// eight points' dot products, the bias is added, and the sums go to
/// `sink`: the largest to a max-pool (the output step is non-decreasing),
/// all eight through the output step to a store.
#[target_feature(enable = "avx2")]
#[inline]
fn outputs(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    sink: &mut Sink<'_>,
    mut sum: impl FnMut(&[u8]) -> __m256i,
) {
    let channels = rows(weights, inputs)
        .zip(le_i32s(q.bias))
        .zip(le_i32s(q.multiplier))
        .zip(q.shift);
    for (o, (((row, bias), m), &s)) in channels.enumerate() {
        let sum = _mm256_add_epi32(sum(row), _mm256_set1_epi32(bias));
        let step = OutputStep::new(m, s as i8, q.zero_point, q.act_min);
        match sink {
            Sink::Pool(_) => sink.take(o, 0, &[max(sum)], &step),
            Sink::Store { out, outputs } => {
                for (t, v) in store(activations(sum, &step)).into_iter().enumerate() {
                    if let Some(y) = out.get_mut(t * *outputs + o) {
                        *y = v as i8;
                    }
                }
            }
        }
    }
}

/// The lane sums of eight vectors, as one: lane `t` is the sum of
/// `acc[t]`'s eight lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn reduce(acc: [__m256i; ROWS]) -> __m256i {
    let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
    // Per 128-bit half: pairs, then quads, of lanes.
    let s0123 = _mm256_hadd_epi32(_mm256_hadd_epi32(a0, a1), _mm256_hadd_epi32(a2, a3));
    let s4567 = _mm256_hadd_epi32(_mm256_hadd_epi32(a4, a5), _mm256_hadd_epi32(a6, a7));
    // Low halves of both, plus high halves of both: [t0..t3, t4..t7].
    _mm256_add_epi32(
        _mm256_permute2x128_si256::<0x20>(s0123, s4567),
        _mm256_permute2x128_si256::<0x31>(s0123, s4567),
    )
}

#[cfg(test)]
mod tests {
    use super::super::test_layer::{TestLayer, byte, vector_cases};
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// The AVX2 tile gives the portable kernel's activations, stored and
    /// max-pooled, on widths with and without a tail past 16, on the
    /// fast and the general requantization paths.
    #[test]
    fn avx2_tile_matches_portable() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = SplitMix64(11);
        for &(inputs, outputs) in &[
            (16, 8),
            (24, 64),
            (32, 64),
            (40, 7),
            (64, 128),
            (128, 33),
            (256, 16),
        ] {
            for shift_range in [(-22, -2), (-31, 31)] {
                let layer = TestLayer::new(&mut rng, inputs, outputs, shift_range);
                let (weights, q) = (&layer.weights, layer.requant());
                let x: Vec<i8> = (0..ROWS * inputs).map(|_| byte(&mut rng)).collect();
                let mut expanded = std::vec![0u32; ROWS * inputs / 2];
                let (mut want, mut got) = (
                    std::vec![0i8; ROWS * outputs],
                    std::vec![0i8; ROWS * outputs],
                );
                super::super::dense_tile(
                    weights,
                    inputs,
                    q,
                    &x,
                    &mut Sink::Store {
                        out: &mut want,
                        outputs,
                    },
                );
                let sink = &mut Sink::Store {
                    out: &mut got,
                    outputs,
                };
                assert!(dense_tile(weights, inputs, q, &x, &mut expanded, sink));
                assert_eq!(got, want, "stored, {inputs} -> {outputs}");
                let (mut want, mut got) =
                    (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
                super::super::dense_tile(weights, inputs, q, &x, &mut Sink::Pool(&mut want));
                assert!(dense_tile(
                    weights,
                    inputs,
                    q,
                    &x,
                    &mut expanded,
                    &mut Sink::Pool(&mut got)
                ));
                assert_eq!(got, want, "pooled, {inputs} -> {outputs}");
            }
        }
    }

    /// The first layer's kernel gives the portable loop's activations,
    /// stored and max-pooled, with extreme coordinates.
    #[test]
    fn avx2_points_match_portable() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = SplitMix64(12);
        for outputs in [1, 7, 32, 64] {
            let weights: Vec<u8> = (0..3 * outputs).map(|_| rng.int(-128, 127) as u8).collect();
            let mut points: Vec<i16> = (0..3 * ROWS)
                .map(|_| rng.int(-32767, 32767) as i16)
                .collect();
            points[0] = i16::MAX;
            points[4] = -i16::MAX;
            let words = |rng: &mut SplitMix64, lo: i32, hi: i32| -> Vec<u8> {
                (0..outputs)
                    .flat_map(|_| rng.int(lo, hi).to_le_bytes())
                    .collect()
            };
            let (bias, multiplier) = (
                words(&mut rng, -1 << 20, 1 << 20),
                words(&mut rng, 1 << 30, i32::MAX),
            );
            let shift: Vec<u8> = (0..outputs).map(|_| rng.int(-31, 31) as i8 as u8).collect();
            let q = Requant {
                bias: &bias,
                multiplier: &multiplier,
                shift: &shift,
                zero_point: -5,
                act_min: -5,
            };
            let (mut want, mut got) = (
                std::vec![0i8; ROWS * outputs],
                std::vec![0i8; ROWS * outputs],
            );
            super::super::portable_points(
                &weights,
                q,
                &points,
                &mut Sink::Store {
                    out: &mut want,
                    outputs,
                },
            );
            assert!(dense_points(
                &weights,
                q,
                &points,
                &mut Sink::Store {
                    out: &mut got,
                    outputs
                }
            ));
            assert_eq!(got, want, "stored, 3 -> {outputs}");
            let (mut want, mut got) = (std::vec![i8::MIN; outputs], std::vec![i8::MIN; outputs]);
            super::super::portable_points(&weights, q, &points, &mut Sink::Pool(&mut want));
            assert!(dense_points(
                &weights,
                q,
                &points,
                &mut Sink::Pool(&mut got)
            ));
            assert_eq!(got, want, "pooled, 3 -> {outputs}");
        }
    }

    /// The head's vector kernels, AVX2 and (where the CPU has them)
    /// AVX-512 VNNI and AVX-VNNI, give the portable kernel's activations
    /// ([`super::super::test_layer::vector_cases`]).
    #[test]
    fn vector_kernels_match_portable() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let vnni = has_vnni();
        if !vnni {
            std::eprintln!("no AVX-512 VNNI on this CPU: vnni::vector not tested");
        }
        let avxvnni = has_avxvnni();
        if !avxvnni {
            std::eprintln!("no AVX-VNNI on this CPU: vnni::vector_avx not tested");
        }
        for c in vector_cases(13) {
            let (inputs, outputs) = (c.x.len(), c.want.len());
            let (a, b) = c.x.split_at(c.split);
            let folded = c.folded_bias();
            let q = c.layer.requant();
            // As given, and with the first part folded into the biases
            // (`skip`), where the second part is wide enough.
            let mut runs = std::vec![(0, std::vec![a, b], q)];
            if b.len() >= LANES {
                let q = Requant { bias: &folded, ..q };
                runs.push((c.split, std::vec![b], q));
            }
            let w = &c.layer.weights;
            for (skip, parts, q) in runs {
                let n: usize = parts.iter().map(|p| p.len()).sum();
                let mut expanded = std::vec![0u32; n.div_ceil(2)];
                let mut got = std::vec![0i8; outputs];
                let what = std::format!("{inputs} -> {outputs}, skip {skip}");
                assert!(dense_vector_avx2(
                    w,
                    skip,
                    &parts,
                    n,
                    q,
                    &mut expanded,
                    &mut got
                ));
                assert_eq!(got, c.want, "AVX2, {what}");
                if vnni {
                    got.fill(0);
                    // SAFETY: the CPU has AVX-512 VNNI and BW (checked above).
                    #[allow(unsafe_code)]
                    unsafe {
                        vnni::vector(w, skip, &parts, q, &mut got)
                    };
                    assert_eq!(got, c.want, "VNNI, {what}");
                }
                if avxvnni {
                    got.fill(0);
                    // SAFETY: the CPU has AVX-VNNI and AVX2 (checked above).
                    #[allow(unsafe_code)]
                    unsafe {
                        vnni::vector_avx(w, skip, &parts, q, &mut got)
                    };
                    assert_eq!(got, c.want, "AVX-VNNI, {what}");
                }
            }
        }
    }

    /// Tiles the kernel does not take are left to the portable path.
    #[test]
    fn declines_partial_tiles_and_narrow_inputs() {
        let (weights, x, mut expanded) = ([0u8; 64], [0i8; 64], [0u32; 64]);
        let q = Requant {
            bias: &[0; 16],
            multiplier: &[0; 16],
            shift: &[0; 4],
            zero_point: 0,
            act_min: 0,
        };
        let mut out = [0i8; 32];
        // Eight points of 8 inputs: too narrow.
        assert!(!dense_tile(
            &weights,
            8,
            q,
            &x,
            &mut expanded,
            &mut Sink::Store {
                out: &mut out,
                outputs: 4
            }
        ));
        // Three points of 16 inputs: not a full tile.
        assert!(!dense_tile(
            &weights,
            16,
            q,
            &x[..48],
            &mut expanded,
            &mut Sink::Store {
                out: &mut out,
                outputs: 4
            }
        ));
    }
}
