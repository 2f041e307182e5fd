//! The int8 dense kernel, used by every quantized layer.

use crate::fixed::{requantize, to_activation};
use crate::format::le_i32s;

/// A stored quantized value that widens to `i32` for accumulation.
pub(crate) trait QValue: Copy {
    /// The value as i32.
    fn widen(self) -> i32;
    /// `sum_i w[i] * x[i]` over the common length (see [`dot`]).
    #[inline(always)]
    fn dot(w: &[u8], x: &[Self]) -> i32 {
        scalar_dot(w, x)
    }
    /// `(dot(w, a), dot(w, b))`.
    #[inline(always)]
    fn dot2(w: &[u8], a: &[Self], b: &[Self]) -> (i32, i32) {
        (Self::dot(w, a), Self::dot(w, b))
    }
}

impl QValue for i8 {
    #[inline(always)]
    fn widen(self) -> i32 {
        self as i32
    }
    #[inline(always)]
    fn dot(w: &[u8], x: &[Self]) -> i32 {
        int8_dot(w, x, |v| v as u8)
    }
    #[inline(always)]
    fn dot2(w: &[u8], a: &[Self], b: &[Self]) -> (i32, i32) {
        int8_dot2(w, a, b)
    }
}

impl QValue for i16 {
    #[inline(always)]
    fn widen(self) -> i32 {
        self as i32
    }
}

/// An int8 value stored as a byte of a blob.
impl QValue for u8 {
    #[inline(always)]
    fn widen(self) -> i32 {
        self as i8 as i32
    }
    #[inline(always)]
    fn dot(w: &[u8], x: &[Self]) -> i32 {
        int8_dot(w, x, |v| v)
    }
}

/// `sum_i w[i] * x[i]` in i32 over the common length. Model loading bounds
/// `|bias| + sum_i |w[i]| * max|x|` by `i32::MAX`, so no partial sum ever
/// leaves the i32 range: every summation order gives the same exact result,
/// which is what lets the DSP kernel below differ from the portable one in
/// order but not in value. (The wrapping operations only keep overflow
/// checks out of the hot loop.)
#[inline(always)]
pub(crate) fn dot<X: QValue>(w: &[u8], x: &[X]) -> i32 {
    X::dot(w, x)
}

#[inline(always)]
fn scalar_dot<X: QValue>(w: &[u8], x: &[X]) -> i32 {
    w.iter().zip(x).fold(0i32, |acc, (&w, &x)| {
        acc.wrapping_add((w as i8 as i32).wrapping_mul(x.widen()))
    })
}

/// Dot product of int8 weights with int8 values (given as bytes by `byte`).
#[cfg(not(pcrnet_arm_dsp))]
#[inline(always)]
fn int8_dot<X: QValue>(w: &[u8], x: &[X], _byte: impl Fn(X) -> u8) -> i32 {
    scalar_dot(w, x)
}

/// Two dot products sharing one weight row.
#[cfg(not(pcrnet_arm_dsp))]
#[inline(always)]
fn int8_dot2(w: &[u8], a: &[i8], b: &[i8]) -> (i32, i32) {
    (scalar_dot(w, a), scalar_dot(w, b))
}

/// Two dot products sharing one weight row: each weight word is loaded and
/// sign-extended once for both rows (8 MACs per 13 instructions in the loop
/// body instead of 4 per 8).
#[cfg(pcrnet_arm_dsp)]
#[inline(always)]
fn int8_dot2(w: &[u8], a: &[i8], b: &[i8]) -> (i32, i32) {
    let n = w.len().min(a.len()).min(b.len());
    let (w, a, b) = (&w[..n], &a[..n], &b[..n]);
    let (wc, ac, bc) = (w.chunks_exact(4), a.chunks_exact(4), b.chunks_exact(4));
    let tail_a = scalar_dot(wc.remainder(), ac.remainder());
    let tail_b = scalar_dot(wc.remainder(), bc.remainder());
    let word = |c: &[i8]| u32::from_le_bytes([c[0] as u8, c[1] as u8, c[2] as u8, c[3] as u8]);
    let (mut acc_a, mut acc_b) = (0i32, 0i32);
    for ((w4, a4), b4) in wc.zip(ac).zip(bc) {
        let wv = u32::from_le_bytes([w4[0], w4[1], w4[2], w4[3]]);
        let (we, wo) = (dsp::sxtb16(wv), dsp::sxtb16_ror8(wv));
        let (av, bv) = (word(a4), word(b4));
        acc_a = dsp::smlad(we, dsp::sxtb16(av), acc_a);
        acc_a = dsp::smlad(wo, dsp::sxtb16_ror8(av), acc_a);
        acc_b = dsp::smlad(we, dsp::sxtb16(bv), acc_b);
        acc_b = dsp::smlad(wo, dsp::sxtb16_ror8(bv), acc_b);
    }
    (acc_a.wrapping_add(tail_a), acc_b.wrapping_add(tail_b))
}

/// Dot product of int8 weights with int8 values, four at a time with the
/// Cortex-M4 DSP instructions (as CMSIS-NN): one 32-bit load per operand,
/// `SXTB16` to sign-extend bytes 0,2 and (rotated) 1,3 into 16-bit pairs,
/// and two `SMLAD` (two 16x16 multiplies and an accumulate each).
#[cfg(pcrnet_arm_dsp)]
#[inline(always)]
fn int8_dot<X: QValue>(w: &[u8], x: &[X], byte: impl Fn(X) -> u8) -> i32 {
    let n = w.len().min(x.len());
    let (w, x) = (&w[..n], &x[..n]);
    let (wc, xc) = (w.chunks_exact(4), x.chunks_exact(4));
    let tail = scalar_dot(wc.remainder(), xc.remainder());
    let mut acc = 0i32;
    for (w4, x4) in wc.zip(xc) {
        let wv = u32::from_le_bytes([w4[0], w4[1], w4[2], w4[3]]);
        let xv = u32::from_le_bytes([byte(x4[0]), byte(x4[1]), byte(x4[2]), byte(x4[3])]);
        acc = dsp::smlad(dsp::sxtb16(wv), dsp::sxtb16(xv), acc);
        acc = dsp::smlad(dsp::sxtb16_ror8(wv), dsp::sxtb16_ror8(xv), acc);
    }
    acc.wrapping_add(tail)
}

/// The three DSP instructions, as register-only inline assembly (stable
/// Rust has no ARM DSP intrinsics).
#[cfg(pcrnet_arm_dsp)]
#[allow(unsafe_code)]
mod dsp {
    use core::arch::asm;

    /// Sign-extends bytes 0 and 2 into two 16-bit halves.
    #[inline(always)]
    pub fn sxtb16(x: u32) -> u32 {
        let r;
        // SAFETY: register-only arithmetic, no memory or flags touched.
        unsafe {
            asm!("sxtb16 {0}, {1}", out(reg) r, in(reg) x, options(pure, nomem, nostack, preserves_flags))
        };
        r
    }

    /// Sign-extends bytes 1 and 3 into two 16-bit halves.
    #[inline(always)]
    pub fn sxtb16_ror8(x: u32) -> u32 {
        let r;
        // SAFETY: register-only arithmetic, no memory or flags touched.
        unsafe {
            asm!("sxtb16 {0}, {1}, ror #8", out(reg) r, in(reg) x, options(pure, nomem, nostack, preserves_flags))
        };
        r
    }

    /// `acc + a.lo * b.lo + a.hi * b.hi` (16-bit halves, signed).
    #[inline(always)]
    pub fn smlad(a: u32, b: u32, acc: i32) -> i32 {
        let r;
        // SAFETY: register-only arithmetic; SMLAD may set the sticky Q flag,
        // which nothing reads (and which cannot be set here, see `dot`).
        unsafe {
            asm!("smlad {0}, {1}, {2}, {3}", out(reg) r, in(reg) a, in(reg) b, in(reg) acc, options(pure, nomem, nostack))
        };
        r
    }
}

/// Requantization parameters of one layer's output.
#[derive(Clone, Copy)]
pub(crate) struct Requant<'a> {
    pub bias: &'a [u8],
    pub multiplier: &'a [u8],
    pub shift: &'a [u8],
    pub zero_point: i8,
    /// `max(zero_point, -128)` with ReLU, -128 without.
    pub act_min: i8,
}

/// One dense layer over a tile of rows.
///
/// `x` holds `rows` rows of `inputs` values; `weights` holds `outputs` rows of
/// `inputs` bytes. For every output channel `o` (outer loop, so a weight row
/// is read once per tile) and row `t`, `emit(t, o, y)` receives the int8
/// activation. Only the first `x.len() / inputs` rows are processed.
#[inline(always)]
pub(crate) fn dense_tile<X: QValue>(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[X],
    mut emit: impl FnMut(usize, usize, i8),
) {
    let rows = weights
        .chunks_exact(inputs)
        .zip(le_i32s(q.bias))
        .zip(le_i32s(q.multiplier))
        .zip(q.shift);
    let out = |acc: i32, m: i32, s: u8| {
        to_activation(requantize(acc, m, s as i8), q.zero_point, q.act_min)
    };
    for (o, (((row, bias), m), &s)) in rows.enumerate() {
        // Two rows at a time share each weight load (see `dot2`).
        let mut pairs = x.chunks_exact(2 * inputs);
        let mut t = 0;
        for pair in pairs.by_ref() {
            let (a, b) = pair.split_at(inputs);
            let (da, db) = X::dot2(row, a, b);
            emit(t, o, out(bias.wrapping_add(da), m, s));
            emit(t + 1, o, out(bias.wrapping_add(db), m, s));
            t += 2;
        }
        let rest = pairs.remainder();
        if rest.len() == inputs {
            emit(t, o, out(bias.wrapping_add(dot(row, rest)), m, s));
        }
    }
}
