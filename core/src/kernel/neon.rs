//! The aarch64 tile and head kernels (`std` feature), chosen at run
//! time (with the host scratch and `dotprod`, whole blocks of points take
//! the block kernel instead, [`super::block`]): `SDOT` where the CPU has
//! the dot-product extension (Armv8.2
//! `dotprod`: Cortex-A55/A76 and later, Apple M, Graviton 2+), plain NEON
//! (`SMULL` + `SADALP`) on every other aarch64 CPU (Cortex-A53/A72, the
//! Raspberry Pi 3 and 4).
//!
//! On a full tile of [`ROWS`] points with at least 16 inputs, for every
//! output channel the weight row is read 16 bytes at a time and multiplied
//! with each point's 16 int8 activations, straight from the tile (no
//! widening copy): `SDOT` adds four products into each of four i32 lanes;
//! without it, `SMULL`/`SMULL2` form eight exact int16 products per half
//! and `SADALP` adds them pairwise into the i32 lanes. Each point keeps its
//! own vector of partial sums, summed across lanes (`ADDV`) at the end;
//! inputs past the last multiple of 16 are added by the scalar loop; the
//! bias and the output step follow (the portable [`Sink::take`]). The head's
//! vector kernel does the same for one vector and four rows at a time.
//!
//! Every product and pairwise sum fits in its lane (|w|, |x| <= 128: a
//! product fits int16, two fit i32), and model loading bounds every
//! partial sum (see [`super::dot`]): the result is the portable kernel's,
//! bit for bit, whatever the order. `cargo xtask aarch64-test` runs these
//! tests under `qemu-aarch64` on a CPU with and one without `dotprod`.
//!
//! `SDOT` is written as inline assembly: its intrinsic (`vdotq_s32`) is
//! not stable Rust yet.

use core::arch::aarch64::{
    int8x16_t, int32x4_t, vaddvq_s32, vdupq_n_s32, vget_low_s8, vld1q_s8, vmull_high_s8, vmull_s8,
    vpadalq_s16,
};

use super::{OutputStep, Requant, Sink, row_groups, rows, scalar_dot};
use crate::format::le_i32s;

/// Points per tile of this kernel (the int8 path's largest tile).
const ROWS: usize = crate::arch::MAX_TILE;

/// Inputs per vector.
const LANES: usize = 16;

/// `acc + ` the products of `w` and `x` (16 int8 each), four per i32 lane.
trait Dot {
    /// # Safety
    /// The CPU must have what the implementation's instructions need.
    unsafe fn dot(acc: int32x4_t, w: int8x16_t, x: int8x16_t) -> int32x4_t;
}

/// The dot-product extension's `SDOT`.
struct Sdot;

impl Dot for Sdot {
    #[inline(always)]
    unsafe fn dot(mut acc: int32x4_t, w: int8x16_t, x: int8x16_t) -> int32x4_t {
        // SAFETY: the caller runs on a CPU with `dotprod`; the instruction
        // only reads and writes these registers.
        unsafe {
            core::arch::asm!(
                "sdot {acc:v}.4s, {w:v}.16b, {x:v}.16b",
                acc = inout(vreg) acc,
                w = in(vreg) w,
                x = in(vreg) x,
                options(pure, nomem, nostack, preserves_flags),
            );
        }
        acc
    }
}

/// Baseline NEON: `SMULL`, `SMULL2`, two `SADALP`.
struct Smull;

impl Dot for Smull {
    #[inline(always)]
    unsafe fn dot(acc: int32x4_t, w: int8x16_t, x: int8x16_t) -> int32x4_t {
        // SAFETY: NEON is part of every aarch64 CPU.
        unsafe {
            let low = vmull_s8(vget_low_s8(w), vget_low_s8(x));
            vpadalq_s16(vpadalq_s16(acc, low), vmull_high_s8(w, x))
        }
    }
}

/// `acc + ` the products of `w` and `x`, four per i32 lane (`SDOT`).
///
/// # Safety
/// The CPU must have `dotprod`.
#[inline(always)]
pub(super) unsafe fn sdot(acc: int32x4_t, w: int8x16_t, x: int8x16_t) -> int32x4_t {
    // SAFETY: the caller's.
    unsafe { Sdot::dot(acc, w, x) }
}

/// `SDOT` by element: each i32 lane of `acc` plus the four products of
/// its quad of `x` with quad `K` (0..=3) of `w`.
///
/// # Safety
/// The CPU must have `dotprod`.
#[inline(always)]
pub(super) unsafe fn sdot_lane<const K: i32>(
    mut acc: int32x4_t,
    x: int8x16_t,
    w: int8x16_t,
) -> int32x4_t {
    // SAFETY: the caller runs on a CPU with `dotprod`; the instruction
    // only reads and writes these registers.
    unsafe {
        core::arch::asm!(
            "sdot {acc:v}.4s, {x:v}.16b, {w:v}.4b[{k}]",
            acc = inout(vreg) acc,
            x = in(vreg) x,
            w = in(vreg) w,
            k = const K,
            options(pure, nomem, nostack, preserves_flags),
        );
    }
    acc
}

/// Whether the CPU has `SDOT`.
pub(super) fn has_sdot() -> bool {
    std::arch::is_aarch64_feature_detected!("dotprod")
}

/// [`super::dense_tile`]'s contract and results for a full tile of
/// [`ROWS`] points with at least 16 inputs. Returns `false`, having done
/// nothing, on any other tile.
pub(super) fn dense_tile(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[i8],
    sink: &mut Sink<'_>,
) -> bool {
    if inputs < LANES || x.len() != ROWS * inputs {
        return false;
    }
    if has_sdot() {
        // SAFETY: the CPU has `dotprod` (checked above).
        unsafe { tile_sdot(weights, inputs, q, x, sink) }
    } else {
        // SAFETY: `Smull` needs only NEON.
        unsafe { tile::<Smull>(weights, inputs, q, x, sink) }
    }
    true
}

#[target_feature(enable = "dotprod")]
fn tile_sdot(weights: &[u8], inputs: usize, q: Requant<'_>, x: &[i8], sink: &mut Sink<'_>) {
    // SAFETY: this function requires `dotprod` of its callers.
    unsafe { tile::<Sdot>(weights, inputs, q, x, sink) }
}

/// # Safety
/// The CPU must have what `D` needs.
#[inline(always)]
unsafe fn tile<D: Dot>(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[i8],
    sink: &mut Sink<'_>,
) {
    let full = inputs / LANES * LANES;
    let mut points = rows(x, inputs);
    let points: [&[i8]; ROWS] = core::array::from_fn(|_| points.next().unwrap_or(&[]));
    let channels = rows(weights, inputs)
        .zip(le_i32s(q.bias))
        .zip(le_i32s(q.multiplier))
        .zip(q.shift);
    for (o, (((row, bias), m), &s)) in channels.enumerate() {
        let (body, tail) = row.split_at(full);
        // SAFETY: NEON is part of every aarch64 CPU.
        let mut acc = [unsafe { vdupq_n_s32(0) }; ROWS];
        for (c, w) in body.chunks_exact(LANES).enumerate() {
            // SAFETY: `w` is 16 bytes, and every point's row holds
            // `inputs >= full` values, so 16 from `c * 16 < full` are in
            // bounds; NEON loads need no alignment. `D`'s needs are this
            // function's callers'.
            unsafe {
                let w = vld1q_s8(w.as_ptr().cast::<i8>());
                for (acc, p) in acc.iter_mut().zip(points) {
                    *acc = D::dot(*acc, w, vld1q_s8(p.as_ptr().add(c * LANES)));
                }
            }
        }
        let mut sums = [0i32; ROWS];
        for ((sum, acc), p) in sums.iter_mut().zip(acc).zip(points) {
            // SAFETY: NEON is part of every aarch64 CPU.
            let lanes = unsafe { vaddvq_s32(acc) };
            let rest = scalar_dot(tail, p.get(full..).unwrap_or(&[]));
            *sum = bias.wrapping_add(lanes).wrapping_add(rest);
        }
        sink.take(
            o,
            0,
            &sums,
            &OutputStep::new(m, s as i8, q.zero_point, q.act_min),
        );
    }
}

/// [`super::dense_vector`]'s contract and results for a vector of at
/// least 16 inputs (the concatenation of `parts`): the parts are copied
/// into one int8 vector in `expanded` (its bytes), then four weight rows
/// at a time are multiplied with it 16 inputs at a time. Returns `false`,
/// having done nothing, on a narrower vector or when `expanded` cannot
/// hold the copy.
pub(super) fn dense_vector(
    weights: &[u8],
    skip: usize,
    parts: &[&[u8]],
    q: Requant<'_>,
    expanded: &mut [u32],
    out: &mut [i8],
) -> bool {
    let inputs: usize = parts.iter().map(|p| p.len()).sum();
    if inputs < LANES {
        return false;
    }
    let Some(xs) = super::as_bytes(expanded).get_mut(..inputs) else {
        return false;
    };
    for (d, &s) in xs.iter_mut().zip(parts.iter().flat_map(|p| p.iter())) {
        *d = s as i8;
    }
    if has_sdot() {
        // SAFETY: the CPU has `dotprod` (checked above).
        unsafe { vector_sdot(weights, skip, inputs, q, xs, out) }
    } else {
        // SAFETY: `Smull` needs only NEON.
        unsafe { vector::<Smull>(weights, skip, inputs, q, xs, out) }
    }
    true
}

#[target_feature(enable = "dotprod")]
fn vector_sdot(
    weights: &[u8],
    skip: usize,
    inputs: usize,
    q: Requant<'_>,
    xs: &[i8],
    out: &mut [i8],
) {
    // SAFETY: this function requires `dotprod` of its callers.
    unsafe { vector::<Sdot>(weights, skip, inputs, q, xs, out) }
}

/// # Safety
/// The CPU must have what `D` needs.
#[inline(always)]
unsafe fn vector<D: Dot>(
    weights: &[u8],
    skip: usize,
    inputs: usize,
    q: Requant<'_>,
    xs: &[i8],
    out: &mut [i8],
) {
    let full = inputs / LANES * LANES;
    let (body, tail) = xs.split_at(full.min(xs.len()));
    for (rs, channels) in row_groups(weights, skip, inputs, q, out) {
        // SAFETY: NEON is part of every aarch64 CPU.
        let mut acc = [unsafe { vdupq_n_s32(0) }; 4];
        for (c, x) in body.chunks_exact(LANES).enumerate() {
            // SAFETY: `x` is 16 values and every row holds `inputs >=
            // full` bytes, so 16 from `c * 16 < full` are in bounds; NEON
            // loads need no alignment. `D`'s needs are this function's
            // callers'.
            unsafe {
                let x = vld1q_s8(x.as_ptr());
                for (acc, r) in acc.iter_mut().zip(rs) {
                    let w = vld1q_s8(r.as_ptr().add(c * LANES).cast::<i8>());
                    *acc = D::dot(*acc, w, x);
                }
            }
        }
        for ((channel, row), acc) in channels.into_iter().zip(rs).zip(acc) {
            let Some((bias, step, y)) = channel else {
                continue;
            };
            // SAFETY: NEON is part of every aarch64 CPU.
            let lanes = unsafe { vaddvq_s32(acc) };
            let rest = scalar_dot(row.get(full..).unwrap_or(&[]), tail);
            *y = step.apply(bias.wrapping_add(lanes).wrapping_add(rest));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_layer::{TestLayer, byte, vector_cases};
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec::Vec;

    /// A tile kernel run into a sink.
    type Kernel<'a> = &'a dyn Fn(&mut Sink<'_>);

    /// Both tile kernels (`SDOT` where the CPU has it, and `SMULL`) give
    /// the portable kernel's activations, stored and max-pooled, on widths
    /// with and without a tail past 16, on the fast and the general
    /// requantization paths.
    #[test]
    fn neon_tile_matches_portable() {
        let mut rng = SplitMix64(17);
        for &(inputs, outputs) in &[(16, 8), (24, 64), (40, 7), (64, 128), (128, 33), (256, 16)] {
            for shift_range in [(-22, -2), (-31, 31)] {
                let layer = TestLayer::new(&mut rng, inputs, outputs, shift_range);
                let (weights, q) = (&layer.weights, layer.requant());
                let x: Vec<i8> = (0..ROWS * inputs).map(|_| byte(&mut rng)).collect();
                let store = |out: &mut Vec<i8>, run: &dyn Fn(&mut Sink<'_>)| {
                    run(&mut Sink::Store { out, outputs });
                };
                let mut want = std::vec![0i8; ROWS * outputs];
                store(&mut want, &|s| {
                    super::super::dense_tile(weights, inputs, q, &x, s)
                });
                let mut pooled = std::vec![i8::MIN; outputs];
                super::super::dense_tile(weights, inputs, q, &x, &mut Sink::Pool(&mut pooled));
                let kernels: [(&str, Kernel<'_>); 2] = [
                    ("dispatched", &|s| {
                        assert!(dense_tile(weights, inputs, q, &x, s))
                    }),
                    // SAFETY: `Smull` needs only NEON.
                    ("smull", &|s| unsafe {
                        tile::<Smull>(weights, inputs, q, &x, s)
                    }),
                ];
                for (name, run) in kernels {
                    let mut got = std::vec![0i8; ROWS * outputs];
                    store(&mut got, run);
                    assert_eq!(got, want, "{name}, stored, {inputs} -> {outputs}");
                    let mut got = std::vec![i8::MIN; outputs];
                    run(&mut Sink::Pool(&mut got));
                    assert_eq!(got, pooled, "{name}, pooled, {inputs} -> {outputs}");
                }
            }
        }
    }

    /// The head's vector kernels (`SDOT` where the CPU has it, and
    /// `SMULL`) give the portable kernel's activations
    /// ([`super::super::test_layer::vector_cases`]).
    #[test]
    fn neon_vector_matches_portable() {
        for c in vector_cases(19) {
            let (inputs, outputs) = (c.x.len(), c.want.len());
            let (weights, q) = (&c.layer.weights, c.layer.requant());
            let (a, b) = c.x.split_at(c.split);
            let folded = c.folded_bias();
            // As given, and with the first part folded into the biases
            // (`skip`), where the second part is wide enough.
            let mut runs = std::vec![(0, std::vec![a, b], q)];
            if b.len() >= LANES {
                let q = Requant { bias: &folded, ..q };
                runs.push((c.split, std::vec![b], q));
            }
            for (skip, parts, q) in runs {
                let n: usize = parts.iter().map(|p| p.len()).sum();
                let what = std::format!("{inputs} -> {outputs}, skip {skip}");
                let mut expanded = std::vec![0u32; n.div_ceil(4)];
                let mut got = std::vec![0i8; outputs];
                assert!(dense_vector(
                    weights,
                    skip,
                    &parts,
                    q,
                    &mut expanded,
                    &mut got
                ));
                assert_eq!(got, c.want, "dispatched, {what}");
                let xs: Vec<i8> = parts
                    .iter()
                    .flat_map(|p| p.iter())
                    .map(|&v| v as i8)
                    .collect();
                let mut got = std::vec![0i8; outputs];
                // SAFETY: `Smull` needs only NEON.
                unsafe { vector::<Smull>(weights, skip, n, q, &xs, &mut got) };
                assert_eq!(got, c.want, "smull, {what}");
            }
        }
    }

    /// Tiles the kernel does not take are left to the portable path.
    #[test]
    fn declines_partial_tiles_and_narrow_inputs() {
        let (weights, x) = ([0u8; 64], [0i8; 64]);
        let q = Requant {
            bias: &[0; 16],
            multiplier: &[0; 16],
            shift: &[0; 4],
            zero_point: 0,
            act_min: 0,
        };
        let mut out = [0i8; 32];
        let mut sink = Sink::Store {
            out: &mut out,
            outputs: 4,
        };
        // Eight points of 8 inputs: too narrow; three of 16: not a full tile.
        assert!(!dense_tile(&weights, 8, q, &x, &mut sink));
        assert!(!dense_tile(&weights, 16, q, &x[..48], &mut sink));
        let mut small = [0u32; 3];
        assert!(!dense_vector(
            &weights,
            0,
            &[&[0u8; 16]],
            q,
            &mut small,
            &mut [0i8; 4]
        ));
    }
}
