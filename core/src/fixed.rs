//! Fixed-point primitives shared by every int8 kernel.
//!
//! # Rounding
//!
//! Requantization uses **single rounding, half toward +infinity**, the
//! `CMSIS_NN_USE_SINGLE_ROUNDING` variant of CMSIS-NN's `arm_nn_requantize`:
//!
//! ```text
//! r      = 31 - shift                       (0 ..= 62)
//! result = (acc * multiplier + 2^(r-1)) >> r   (in i64, arithmetic shift)
//! ```
//!
//! which is exactly `floor(acc * multiplier / 2^r + 1/2)`: the exact product
//! rounded once to the nearest integer, ties upward. We chose it over
//! TFLite's double rounding (`SaturatingRoundingDoublingHighMul` followed by
//! `RoundingDivideByPOT`) because
//! - it has one rounding step, so the error is at most half an LSB, and the
//!   whole definition can be checked against a plain `i128` reference;
//! - on Cortex-M4 it is `SMULL` + a 64-bit add + a shift, cheaper than
//!   emulating `SQRDMULH`;
//! - it matches CMSIS-NN's single-rounding build, so outputs can be
//!   cross-checked against those kernels.
//!
//! All arithmetic here is integer; the results are bit-identical on every
//! target.

/// Smallest accepted requantization shift (multiply by `2^-31` on top of the Q31 multiplier).
pub const MIN_SHIFT: i8 = -31;
/// Largest accepted requantization shift.
pub const MAX_SHIFT: i8 = 31;

/// Rescales an `i32` accumulator by `multiplier * 2^(shift - 31)`.
///
/// `multiplier` is a Q31 fixed-point number (normally in `[2^30, 2^31)`, see
/// [`quantize_multiplier`]). `shift` outside `MIN_SHIFT..=MAX_SHIFT` is
/// clamped to that range (model loading rejects such shifts, so this only
/// keeps the function total). The result is rounded once, half toward +inf,
/// and saturated to the `i32` range.
#[inline(always)]
pub fn requantize(acc: i32, multiplier: i32, shift: i8) -> i32 {
    let shift = shift.clamp(MIN_SHIFT, MAX_SHIFT);
    // 0 ..= 62
    let r = (31 - shift as i32) as u32;
    // |acc * multiplier| <= 2^62, so adding 2^61 cannot overflow i64.
    let prod = acc as i64 * multiplier as i64;
    if r >= 32 {
        // The usual case (scales below 1/2): the same value computed as a
        // high word and a 32-bit shift (`floor(floor(x / 2^32) / 2^(r-32))
        // = floor(x / 2^r)`), which Cortex-M4 does with SMLAL and ASR
        // instead of a variable 64-bit shift. |result| <= 2^30: no saturation.
        (((prod + half(r)) >> 32) as i32) >> (r - 32)
    } else if r == 0 {
        saturate_i32(prod)
    } else {
        saturate_i32((prod + half(r)) >> r)
    }
}

/// The output step of one channel, `to_activation(requantize(acc,
/// multiplier, shift), zero_point, act_min)`, its parameters decoded once:
/// the kernels apply it to every point of a tile. Bit-identical to those
/// two functions for every input (tested exhaustively over shifts and on
/// random values).
///
/// With `r = 31 - shift >= 33` (scales below 2^-2, every trained layer's
/// case) the rounding offset `2^(r-1)` is a multiple of `2^32`, so the
/// requantized value is `(hi + 2^(r-33)) >> (r-32)` with `hi` the high word
/// of `acc * multiplier`; adding `zero_point << (r-32)` before the shift
/// adds the zero point exactly. One `SMMLA` (high word plus the folded
/// offset), a shift and the clamp: no 64-bit arithmetic, no saturating add
/// (the sum stays below 2^31 when `r - 32 <= 21`). Other shifts take the
/// general path.
#[derive(Clone, Copy)]
pub(crate) struct OutputStep {
    multiplier: i32,
    shift: i8,
    zero_point: i8,
    act_min: i8,
    /// `2^(r-33) + zero_point * 2^(r-32)` (no `2^(r-33)` with truncating
    /// rounding), or `None`: the general path.
    offset: Option<i32>,
    /// `r - 32`.
    high_shift: u32,
}

impl OutputStep {
    /// The step for `multiplier * 2^(shift - 31)`, then `zero_point`, then
    /// the clamp to `[act_min, 127]`.
    #[inline(always)]
    pub(crate) fn new(multiplier: i32, shift: i8, zero_point: i8, act_min: i8) -> Self {
        // r - 32 = -1 - shift: the fast path needs 1 <= r - 32 <= 21. (The
        // general path clamps the shift itself, see `requantize`.)
        let fast = (-22..=-2).contains(&shift);
        let high_shift = if fast { (-1 - shift as i32) as u32 } else { 0 };
        let offset = fast.then(|| {
            let round = if ROUNDS_HALF_UP {
                1i32 << (high_shift - 1)
            } else {
                0
            };
            round + ((zero_point as i32) << high_shift)
        });
        OutputStep {
            multiplier,
            shift,
            zero_point,
            act_min,
            offset,
            high_shift,
        }
    }

    /// The fast path's constants, `(multiplier, offset, high_shift,
    /// act_min)`, for kernels that apply the step to several accumulators
    /// at once: the activation is `clamp((hi(acc * multiplier) + offset)
    /// >> high_shift, act_min, 127)`, `hi` the high 32 bits of the i64
    /// product. `None` for the general path (use [`Self::apply`]).
    #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
    #[inline(always)]
    pub(crate) fn fast_parts(&self) -> Option<(i32, i32, u32, i8)> {
        self.offset
            .map(|offset| (self.multiplier, offset, self.high_shift, self.act_min))
    }

    /// The ReLU floor of the clamp (the activation of a negative
    /// accumulator, or -128 without ReLU).
    #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
    pub(crate) fn act_min(&self) -> i8 {
        self.act_min
    }

    /// The int8 activation of accumulator `acc`.
    #[inline(always)]
    pub(crate) fn apply(&self, acc: i32) -> i8 {
        match self.offset {
            Some(offset) => {
                // |hi| <= 2^30, 0 <= 2^(r-33) <= 2^20 and |zero_point <<
                // high_shift| <= 2^28: the sum cannot overflow.
                let hi = ((acc as i64 * self.multiplier as i64) >> 32) as i32;
                let v = (hi + offset) >> self.high_shift;
                // Saturate to int8 (one SSAT on Cortex-M), then the ReLU floor.
                v.clamp(i8::MIN as i32, i8::MAX as i32)
                    .max(self.act_min as i32) as i8
            }
            None => general_step(
                acc,
                self.multiplier,
                self.shift,
                self.zero_point,
                self.act_min,
            ),
        }
    }
}

/// The output step for shifts outside the fast path's range. Out of line
/// and cold: inlined, LLVM computes its 64-bit constants ahead of the
/// branch for every output, which is most of a head row's overhead.
#[cold]
#[inline(never)]
fn general_step(acc: i32, multiplier: i32, shift: i8, zero_point: i8, act_min: i8) -> i8 {
    to_activation(requantize(acc, multiplier, shift), zero_point, act_min)
}

/// Whether requantization rounds half up (always, but for the QEMU
/// harness's self-test: it proves it notices a changed rounding by building
/// the device with the `mutate-rounding` feature, which truncates, i.e.
/// rounds toward -infinity, instead).
const ROUNDS_HALF_UP: bool = !cfg!(feature = "mutate-rounding");

/// The rounding offset `2^(r-1)` (half toward +infinity).
#[inline(always)]
fn half(r: u32) -> i64 {
    if ROUNDS_HALF_UP { 1i64 << (r - 1) } else { 0 }
}

/// Clamps an `i64` into the `i32` range.
#[inline(always)]
fn saturate_i32(v: i64) -> i32 {
    if v > i32::MAX as i64 {
        i32::MAX
    } else if v < i32::MIN as i64 {
        i32::MIN
    } else {
        v as i32
    }
}

/// Turns a requantized value into an int8 activation: adds the output zero
/// point and clamps to `[act_min, 127]`. With `act_min = max(zero_point, -128)`
/// the clamp is the fused ReLU.
#[inline(always)]
pub fn to_activation(scaled: i32, zero_point: i8, act_min: i8) -> i8 {
    let v = scaled.saturating_add(zero_point as i32);
    if v < act_min as i32 {
        act_min
    } else if v > i8::MAX as i32 {
        i8::MAX
    } else {
        v as i8
    }
}

/// Splits a positive real scale into a Q31 multiplier and a shift so that
/// `scale ~= multiplier * 2^(shift - 31)` with `multiplier` in `[2^30, 2^31)`.
///
/// Returns `None` for non-positive, non-finite, or too large scales
/// (`scale >= 2^31`). Scales below `2^-32` cannot be represented with
/// `shift >= -31`; they return multiplier 0 (every output is then the zero point).
/// Used by the host when quantizing; the device only reads the results.
pub fn quantize_multiplier(scale: f64) -> Option<(i32, i8)> {
    if !scale.is_finite() || scale <= 0.0 {
        return None;
    }
    let (mantissa, exp) = libm::frexp(scale); // scale = mantissa * 2^exp, mantissa in [0.5, 1)
    let mut q = libm::round(mantissa * (1u64 << 31) as f64) as i64;
    let mut exp = exp;
    if q == 1i64 << 31 {
        q /= 2;
        exp += 1;
    }
    if exp > MAX_SHIFT as i32 {
        return None;
    }
    if exp < MIN_SHIFT as i32 {
        return Some((0, 0));
    }
    Some((q as i32, exp as i8))
}

/// The largest magnitude of a quantized input coordinate.
pub const INPUT_QMAX: i16 = i16::MAX;

/// Quantizes one input coordinate to int16 with zero point 0:
/// `q = round_half_away_from_zero(x / scale)`.
///
/// The division is a single IEEE-754 f32 operation and the rounding is
/// `libm::roundf`, so the result is identical on every target. Returns
/// `None` when `x` is not finite or `|x / scale| > 32767` (the caller
/// reports which point).
#[inline]
pub fn quantize_coordinate(x: f32, scale: f32) -> Option<i16> {
    let r = libm::roundf(x / scale);
    if r.is_finite() && libm::fabsf(r) <= INPUT_QMAX as f32 {
        Some(r as i16)
    } else {
        None
    }
}

/// `x` rounded half away from zero to the int16 grid and clamped to
/// `-32767..=32767` (NaN gives 0): the value of
/// `libm::roundf(x).clamp(-32767.0, 32767.0) as i16`, without `roundf`'s
/// bit manipulation (about 20 instructions a call on a Cortex-M4, where
/// this is a clamp, one `VCVT` and one subtraction).
///
/// Exact on every target: after the clamp to `c`, the truncation `t = c
/// as i32` and `c - t` (the fractional part, representable because `|c| <
/// 2^15`) are exact, so comparing the fraction with one half decides the
/// rounding as `roundf` does. Checked against `libm::roundf` on every
/// f32 once (all 2^32, session 48), and in tests on a stride through
/// them, every half-integer of the grid and its neighbours, and the
/// special values.
#[inline(always)]
pub fn round_clamped_i16(x: f32) -> i16 {
    let c = x.clamp(-(INPUT_QMAX as f32), INPUT_QMAX as f32);
    let t = c as i32;
    let fraction = c - t as f32;
    let r = if fraction >= 0.5 {
        t + 1
    } else if fraction <= -0.5 {
        t - 1
    } else {
        t
    };
    r as i16
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Plain i128 reference of [`requantize`]: floor(acc*m/2^r + 1/2), saturated.
    fn requantize_ref(acc: i32, m: i32, shift: i8) -> i32 {
        let shift = shift.clamp(MIN_SHIFT, MAX_SHIFT);
        let r = 31 - shift as i32;
        let num = acc as i128 * m as i128;
        let den = 1i128 << r;
        // floor((2*num + den) / (2*den))
        let v = (2 * num + den).div_euclid(2 * den);
        v.clamp(i32::MIN as i128, i32::MAX as i128) as i32
    }

    const EXTREMES: [i32; 9] = [
        i32::MIN,
        i32::MIN + 1,
        -65536,
        -1,
        0,
        1,
        65535,
        i32::MAX - 1,
        i32::MAX,
    ];

    #[test]
    fn requantize_extremes_every_shift() {
        for &acc in &EXTREMES {
            for &m in &EXTREMES {
                for shift in -40i8..=40 {
                    assert_eq!(
                        requantize(acc, m, shift),
                        requantize_ref(acc, m, shift),
                        "acc {acc} m {m} shift {shift}"
                    );
                }
            }
        }
    }

    #[test]
    fn requantize_exhaustive_small_accumulators() {
        // Every accumulator in +-2^12 for a spread of multipliers and all shifts.
        let ms = [1 << 30, (1 << 30) + 12345, i32::MAX, 1_518_500_250];
        for &m in &ms {
            for shift in MIN_SHIFT..=MAX_SHIFT {
                for acc in -4096..=4096 {
                    assert_eq!(requantize(acc, m, shift), requantize_ref(acc, m, shift));
                }
            }
        }
    }

    #[test]
    fn ties_round_up() {
        // multiplier 2^30 with shift 0 halves: 3/2 -> 2, -3/2 -> -1, 1/2 -> 1, -1/2 -> 0.
        assert_eq!(requantize(3, 1 << 30, 0), 2);
        assert_eq!(requantize(-3, 1 << 30, 0), -1);
        assert_eq!(requantize(1, 1 << 30, 0), 1);
        assert_eq!(requantize(-1, 1 << 30, 0), 0);
        // shift 31 is a pure multiply by the (integer) multiplier, saturated.
        assert_eq!(requantize(2, 7, 31), 14);
        assert_eq!(requantize(i32::MIN, i32::MAX, 31), i32::MIN);
    }

    #[test]
    fn activation_exhaustive() {
        for zp in i8::MIN..=i8::MAX {
            for act_min in [i8::MIN, zp] {
                for v in -300..=300 {
                    let want = (v + zp as i32).clamp(act_min as i32, 127) as i8;
                    assert_eq!(to_activation(v, zp, act_min), want);
                }
                assert_eq!(to_activation(i32::MAX, zp, act_min), 127);
                assert_eq!(to_activation(i32::MIN, zp, act_min), act_min);
            }
        }
    }

    #[test]
    fn quantize_multiplier_edges() {
        assert_eq!(quantize_multiplier(0.0), None);
        assert_eq!(quantize_multiplier(-1.0), None);
        assert_eq!(quantize_multiplier(f64::NAN), None);
        assert_eq!(quantize_multiplier(f64::INFINITY), None);
        assert_eq!(quantize_multiplier(0.5), Some((1 << 30, 0)));
        assert_eq!(quantize_multiplier(1.0), Some((1 << 30, 1)));
        // Mantissa rounding up to 2^31 renormalises.
        assert_eq!(quantize_multiplier(1.0 - 1e-12), Some((1 << 30, 1)));
        assert_eq!(quantize_multiplier(1e-12), Some((0, 0)));
        assert_eq!(quantize_multiplier(3e9), None);
    }

    #[test]
    fn quantize_coordinate_edges() {
        assert_eq!(quantize_coordinate(0.0, 0.001), Some(0));
        assert_eq!(quantize_coordinate(0.0005, 0.001), Some(1)); // half away from zero
        assert_eq!(quantize_coordinate(-0.0005, 0.001), Some(-1));
        assert_eq!(quantize_coordinate(32.767, 0.001), Some(32767));
        assert_eq!(quantize_coordinate(-32.767, 0.001), Some(-32767));
        assert_eq!(quantize_coordinate(32.768, 0.001), None);
        assert_eq!(quantize_coordinate(f32::NAN, 0.001), None);
        assert_eq!(quantize_coordinate(f32::INFINITY, 0.001), None);
    }

    fn output_step_ref(acc: i32, m: i32, shift: i8, zp: i8, act_min: i8) -> i8 {
        to_activation(requantize(acc, m, shift), zp, act_min)
    }

    #[test]
    fn output_step_equals_requantize_and_activation_at_every_shift() {
        let accs = [
            0,
            1,
            -1,
            2,
            -2,
            3,
            1 << 20,
            -(1 << 20),
            i32::MAX,
            i32::MIN,
            12_345_678,
        ];
        let ms = [0, 1, -1, 1 << 30, i32::MAX, i32::MIN, 1_518_500_250];
        for shift in -35i8..=35 {
            for &m in &ms {
                for (zp, act_min) in [(0, -128), (-128, -128), (127, 127), (-5, -5), (17, -128)] {
                    let step = OutputStep::new(m, shift, zp, act_min);
                    for &acc in &accs {
                        let want = output_step_ref(acc, m, shift, zp, act_min);
                        assert_eq!(step.apply(acc), want, "{acc} {m} {shift} {zp} {act_min}");
                    }
                }
            }
        }
    }

    fn round_reference(x: f32) -> i16 {
        libm::roundf(x).clamp(-32767.0, 32767.0) as i16
    }

    #[test]
    fn round_clamped_matches_roundf() {
        // The ties and their neighbours at every half-integer of the grid
        // and beyond it, a stride through every f32, and the specials.
        for k in -40_000i32..40_000 {
            let tie = k as f32 + 0.5;
            for x in [tie, tie.next_up(), tie.next_down(), k as f32] {
                assert_eq!(round_clamped_i16(x), round_reference(x), "{x}");
            }
        }
        for bits in (0..=u32::MAX).step_by(4099) {
            let x = f32::from_bits(bits);
            assert_eq!(round_clamped_i16(x), round_reference(x), "{bits:#x}");
        }
        for x in [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            f32::MAX,
            f32::MIN,
        ] {
            assert_eq!(round_clamped_i16(x), round_reference(x), "{x}");
        }
    }

    proptest! {
        #[test]
        fn output_step_matches_requantize_and_activation(
            acc in any::<i32>(), m in any::<i32>(), shift in -35i8..=35, zp in any::<i8>(), relu in any::<bool>()
        ) {
            let act_min = if relu { zp } else { i8::MIN };
            prop_assert_eq!(
                OutputStep::new(m, shift, zp, act_min).apply(acc),
                output_step_ref(acc, m, shift, zp, act_min)
            );
        }

        #[test]
        fn requantize_matches_reference(acc in any::<i32>(), m in any::<i32>(), shift in -35i8..=35) {
            prop_assert_eq!(requantize(acc, m, shift), requantize_ref(acc, m, shift));
        }

        #[test]
        fn quantize_multiplier_is_accurate(scale in 1e-9f64..1e9) {
            let (m, s) = quantize_multiplier(scale).unwrap();
            prop_assert!((1 << 30..=i32::MAX).contains(&m));
            let back = m as f64 * libm::pow(2.0, s as f64 - 31.0);
            prop_assert!(((back - scale) / scale).abs() <= 1.0 / (1u64 << 30) as f64);
        }

        #[test]
        fn quantize_coordinate_within_half_step(x in -30.0f32..30.0) {
            let q = quantize_coordinate(x, 0.001).unwrap();
            prop_assert!((q as f64 * 0.001 - x as f64).abs() <= 0.0005 + 1e-6);
        }
    }
}
