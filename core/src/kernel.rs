//! The int8 dense kernel, used by every quantized layer.

use crate::fixed::{requantize, to_activation};
use crate::format::le_i32s;

/// A stored quantized value that widens to `i32` for accumulation.
pub(crate) trait QValue: Copy {
    fn widen(self) -> i32;
}

impl QValue for i8 {
    #[inline(always)]
    fn widen(self) -> i32 {
        self as i32
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
}

/// `sum_i w[i] * x[i]` in i32 over the common length. Model loading bounds
/// `|bias| + sum_i |w[i]| * max|x|` by `i32::MAX`, so the wrapping operations
/// never actually wrap; they only keep overflow checks out of the hot loop.
#[inline(always)]
pub(crate) fn dot<X: QValue>(w: &[u8], x: &[X]) -> i32 {
    w.iter().zip(x).fold(0i32, |acc, (&w, &x)| {
        acc.wrapping_add((w as i8 as i32).wrapping_mul(x.widen()))
    })
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
    for (o, (((row, bias), m), &s)) in rows.enumerate() {
        for (t, xrow) in x.chunks_exact(inputs).enumerate() {
            let acc = bias.wrapping_add(dot(row, xrow));
            emit(
                t,
                o,
                to_activation(requantize(acc, m, s as i8), q.zero_point, q.act_min),
            );
        }
    }
}
