//! The AVX2 output step and lane helpers the x86-64 kernels share: the
//! tile and vector kernels (`super`) and the block kernel's AVX2 and
//! AVX-VNNI routes.

use core::arch::x86_64::{
    __m256i, _mm_cvtsi32_si128, _mm256_add_epi32, _mm256_blend_epi32, _mm256_cvtsi256_si32,
    _mm256_loadu_si256, _mm256_max_epi32, _mm256_min_epi32, _mm256_mul_epi32,
    _mm256_permute2x128_si256, _mm256_set1_epi32, _mm256_shuffle_epi32, _mm256_sra_epi32,
    _mm256_srli_epi64, _mm256_storeu_si256,
};

use crate::fixed::OutputStep;

/// `OutputStep::apply` on eight accumulators (see [`VectorStep`]).
#[inline]
#[target_feature(enable = "avx2")]
pub(in super::super) fn activations(acc: __m256i, step: &OutputStep) -> __m256i {
    VectorStep::new(step).apply(acc)
}

/// An output step made ready for many vectors of eight accumulators: on
/// the fast path its constants ([`OutputStep::fast_parts`]) in every lane,
/// so that a kernel broadcasts them once per output, not per vector.
#[derive(Clone, Copy)]
pub(in super::super) enum VectorStep<'a> {
    /// [`high_step`], then the clamp to `act_min..=127`: the same integer
    /// operations as the scalar step, so the same values.
    Fast {
        m: __m256i,
        offset: __m256i,
        high_shift: u32,
        act_min: __m256i,
    },
    /// The general path, lane by lane.
    General(&'a OutputStep),
}

impl<'a> VectorStep<'a> {
    /// `step` made ready.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(in super::super) fn new(step: &'a OutputStep) -> Self {
        match step.fast_parts() {
            Some((m, offset, high_shift, act_min)) => VectorStep::Fast {
                m: _mm256_set1_epi32(m),
                offset: _mm256_set1_epi32(offset),
                high_shift,
                act_min: _mm256_set1_epi32(act_min as i32),
            },
            None => VectorStep::General(step),
        }
    }

    /// The activations of eight accumulators.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(in super::super) fn apply(&self, acc: __m256i) -> __m256i {
        match *self {
            VectorStep::Fast {
                m,
                offset,
                high_shift,
                act_min,
            } => {
                let v = high_step(acc, m, offset, high_shift);
                let v = _mm256_min_epi32(v, _mm256_set1_epi32(i8::MAX as i32));
                _mm256_max_epi32(v, act_min)
            }
            VectorStep::General(step) => load(store(acc).map(|a| step.apply(a) as i32)),
        }
    }
}

/// The fast output step on eight accumulators but for its clamp (`m` and
/// `offset` in every lane): the high words of the eight i64 products with
/// `m` (`VPMULDQ` on the even lanes,
/// then on the odd lanes moved down), the folded offset and the
/// arithmetic shift, as in the scalar step.
#[inline]
#[target_feature(enable = "avx2")]
pub(in super::super) fn high_step(
    acc: __m256i,
    m: __m256i,
    offset: __m256i,
    high_shift: u32,
) -> __m256i {
    let even = _mm256_mul_epi32(acc, m);
    let odd = _mm256_mul_epi32(_mm256_srli_epi64::<32>(acc), m);
    let hi = _mm256_blend_epi32::<0b1010_1010>(_mm256_srli_epi64::<32>(even), odd);
    _mm256_sra_epi32(
        _mm256_add_epi32(hi, offset),
        _mm_cvtsi32_si128(high_shift as i32),
    )
}

/// The largest of eight lanes.
#[inline]
#[target_feature(enable = "avx2")]
pub(in super::super) fn max(v: __m256i) -> i32 {
    let v = _mm256_max_epi32(v, _mm256_permute2x128_si256::<0x01>(v, v));
    let v = _mm256_max_epi32(v, _mm256_shuffle_epi32::<0b01_00_11_10>(v));
    let v = _mm256_max_epi32(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v));
    _mm256_cvtsi256_si32(v)
}

/// Eight i32 as a vector.
#[inline]
#[target_feature(enable = "avx2")]
pub(in super::super) fn load(values: [i32; 8]) -> __m256i {
    // SAFETY: `values` is 32 bytes; unaligned loads are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_loadu_si256(values.as_ptr().cast::<__m256i>())
    }
}

/// A vector's eight i32.
#[inline]
#[target_feature(enable = "avx2")]
pub(in super::super) fn store(v: __m256i) -> [i32; 8] {
    let mut out = [0i32; 8];
    // SAFETY: `out` is 32 bytes; unaligned stores are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), v)
    };
    out
}
