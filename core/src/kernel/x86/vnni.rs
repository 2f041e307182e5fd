//! The head's vector kernels with AVX-512 VNNI or AVX-VNNI (`VPDPBUSD`).

use core::arch::x86_64::{
    __m256i, __m512i, _mm_add_epi32, _mm_cvtsi128_si32, _mm_shuffle_epi32, _mm256_castsi256_si128,
    _mm256_dpbusd_avx_epi32, _mm256_extracti128_si256, _mm256_loadu_si256, _mm256_set1_epi8,
    _mm256_setzero_si256, _mm256_xor_si256, _mm512_dpbusd_epi32, _mm512_loadu_si512,
    _mm512_reduce_add_epi32, _mm512_set1_epi8, _mm512_setzero_si512, _mm512_xor_si512,
};

use super::super::{Requant, dot, row_groups};

/// Whether the CPU has what the AVX-512 VNNI kernels need (VNNI and BW,
/// which imply F).
pub(in super::super) fn has_vnni() -> bool {
    std::is_x86_feature_detected!("avx512vnni") && std::is_x86_feature_detected!("avx512bw")
}

/// Whether the CPU has what the AVX-VNNI kernels need (AVX-VNNI, and AVX2
/// for the rest of their steps).
pub(in super::super) fn has_avxvnni() -> bool {
    std::is_x86_feature_detected!("avxvnni") && std::is_x86_feature_detected!("avx2")
}

/// Defines a head vector kernel on `VPDPBUSD` vectors of `$lanes` bytes
/// (the AVX-512 and the AVX-VNNI one share this body): `$load` reads a
/// chunk, `$dot` is `VPDPBUSD`, `$xor`, `$splat` and `$zero` as named,
/// `$sum` adds a vector's i32 lanes.
macro_rules! vector_kernel {
    ($(#[$doc:meta])* $name:ident, $features:literal, $lanes:literal, $load:ident, $dot:ident,
     $xor:ident, $splat:ident, $zero:ident, $sum:ident) => {
        $(#[$doc])*
        #[target_feature(enable = $features)]
        pub(super) fn $name(
            weights: &[u8],
            skip: usize,
            parts: &[&[u8]],
            q: Requant<'_>,
            out: &mut [i8],
        ) {
            let inputs: usize = parts.iter().map(|p| p.len()).sum();
            let mut sum = 0i32;
            for part in parts {
                let full = part.len() / $lanes * $lanes;
                let body = part.get(..full).unwrap_or(&[]);
                sum = body
                    .iter()
                    .fold(sum, |s, &x| s.wrapping_add(x as i8 as i32));
            }
            let correction = sum.wrapping_mul(128);
            let flip = $splat(i8::MIN);
            for (rs, channels) in row_groups(weights, skip, inputs, q, out) {
                let mut acc = [$zero(); 4];
                let mut tails = [0i32; 4];
                let mut offset = 0;
                for part in parts {
                    let full = part.len() / $lanes * $lanes;
                    let (body, tail) = part.split_at(full);
                    for (c, x) in body.as_chunks::<$lanes>().0.iter().enumerate() {
                        let x = $load(x);
                        for (acc, r) in acc.iter_mut().zip(rs) {
                            let w = r.get(offset + c * $lanes..).and_then(|w| w.first_chunk());
                            if let Some(w) = w {
                                *acc = $dot(*acc, $xor($load(w), flip), x);
                            }
                        }
                    }
                    for (t, r) in tails.iter_mut().zip(rs) {
                        let w = r.get(offset + full..offset + part.len()).unwrap_or(&[]);
                        *t = t.wrapping_add(dot(w, tail));
                    }
                    offset += part.len();
                }
                for ((channel, acc), tail) in channels.into_iter().zip(acc).zip(tails) {
                    if let Some((bias, step, y)) = channel {
                        let sum = $sum(acc).wrapping_sub(correction);
                        *y = step.apply(bias.wrapping_add(sum).wrapping_add(tail));
                    }
                }
            }
        }
    };
}

vector_kernel!(
    /// [`super::super::dense_vector`]'s contract and results on a CPU with
    /// AVX-512 VNNI: a dense layer on one vector, the concatenation of
    /// `parts` (int8 values as bytes), read in place. `VPDPBUSD` takes
    /// unsigned bytes on one side and signed on the other, and here the
    /// weights go unsigned:
    ///
    /// - each weight byte has its top bit flipped, `w ^ 0x80 = w + 128`
    ///   (0..=255), and the inputs stay signed, so a lane adds
    ///   `sum((w + 128) x) = sum(w x) + 128 sum(x)`;
    /// - `128 sum(x)` over the inputs the vectors took is the same for
    ///   every row: it is computed once and taken off each row's sum;
    /// - four rows at a time share each load of 64 inputs, one accumulator
    ///   each, summed across its lanes at the end; each part's inputs past
    ///   its last multiple of 64 go through the scalar dot product.
    ///
    /// Each lane's four products are at most `4 * 255 * 128` in magnitude
    /// and the sums wrap in i32 as the portable kernel's do (model loading
    /// bounds them), so every row's accumulator, and activation, is its
    /// own.
    vector,
    "avx512f,avx512bw,avx512vnni",
    64,
    load64,
    _mm512_dpbusd_epi32,
    _mm512_xor_si512,
    _mm512_set1_epi8,
    _mm512_setzero_si512,
    _mm512_reduce_add_epi32
);

vector_kernel!(
    /// [`vector`] on a CPU with AVX-VNNI but not AVX-512 (Intel's client
    /// cores since Alder Lake): the same steps on 32 inputs at a time.
    vector_avx,
    "avx2,avxvnni",
    32,
    load32,
    _mm256_dpbusd_avx_epi32,
    _mm256_xor_si256,
    _mm256_set1_epi8,
    _mm256_setzero_si256,
    sum32
);

/// 64 bytes as a vector.
#[inline]
#[target_feature(enable = "avx512f")]
fn load64(bytes: &[u8; 64]) -> __m512i {
    // SAFETY: `bytes` is 64 bytes long; unaligned loads are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm512_loadu_si512(bytes.as_ptr().cast())
    }
}

/// 32 bytes as a vector.
#[inline]
#[target_feature(enable = "avx2")]
fn load32(bytes: &[u8; 32]) -> __m256i {
    // SAFETY: `bytes` is 32 bytes long; unaligned loads are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_loadu_si256(bytes.as_ptr().cast())
    }
}

/// The sum of eight i32 lanes (wrapping).
#[inline]
#[target_feature(enable = "avx2")]
fn sum32(v: __m256i) -> i32 {
    let v = _mm_add_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
    let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b01_00_11_10>(v));
    let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b10_11_00_01>(v));
    _mm_cvtsi128_si32(v)
}
