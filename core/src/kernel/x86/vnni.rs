//! The head's vector kernel with AVX-512 VNNI (`VPDPBUSD`).

use core::arch::x86_64::{
    __m512i, _mm512_dpbusd_epi32, _mm512_loadu_si512, _mm512_reduce_add_epi32, _mm512_set1_epi8,
    _mm512_setzero_si512, _mm512_xor_si512,
};

use super::super::{Requant, dot, row_groups};

/// Bytes per `VPDPBUSD`.
const LANES: usize = 64;

/// Whether the CPU has what the AVX-512 VNNI kernels need (VNNI and BW,
/// which imply F).
pub(in super::super) fn has_vnni() -> bool {
    std::is_x86_feature_detected!("avx512vnni") && std::is_x86_feature_detected!("avx512bw")
}

/// [`super::super::dense_vector`]'s contract and results on a CPU with
/// AVX-512 VNNI: a dense layer on one vector, the concatenation of `parts`
/// (int8 values as bytes), read in place. `VPDPBUSD` takes unsigned bytes
/// on one side and signed on the other, and here the weights go unsigned:
///
/// - each weight byte has its top bit flipped, `w ^ 0x80 = w + 128`
///   (0..=255), and the inputs stay signed, so a lane adds
///   `sum((w + 128) x) = sum(w x) + 128 sum(x)`;
/// - `128 sum(x)` over the inputs the vectors took is the same for every
///   row: it is computed once and taken off each row's sum;
/// - four rows at a time share each load of 64 inputs, one accumulator
///   each, summed across its lanes at the end; each part's inputs past its
///   last multiple of 64 go through the scalar dot product.
///
/// Each lane's four products are at most `4 * 255 * 128` in magnitude and
/// the sums wrap in i32 as the portable kernel's do (model loading bounds
/// them), so every row's accumulator, and activation, is its own.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) fn vector(weights: &[u8], parts: &[&[u8]], q: Requant<'_>, out: &mut [i8]) {
    let inputs: usize = parts.iter().map(|p| p.len()).sum();
    let mut sum = 0i32;
    for part in parts {
        let full = part.len() / LANES * LANES;
        let body = part.get(..full).unwrap_or(&[]);
        sum = body
            .iter()
            .fold(sum, |s, &x| s.wrapping_add(x as i8 as i32));
    }
    let correction = sum.wrapping_mul(128);
    let flip = _mm512_set1_epi8(i8::MIN);
    for (rs, channels) in row_groups(weights, inputs, q, out) {
        let mut acc = [_mm512_setzero_si512(); 4];
        let mut tails = [0i32; 4];
        let mut offset = 0;
        for part in parts {
            let full = part.len() / LANES * LANES;
            let (body, tail) = part.split_at(full);
            for (c, x) in body.as_chunks::<LANES>().0.iter().enumerate() {
                let x = load(x);
                for (acc, r) in acc.iter_mut().zip(rs) {
                    let w = r.get(offset + c * LANES..).and_then(|w| w.first_chunk());
                    if let Some(w) = w {
                        *acc = _mm512_dpbusd_epi32(*acc, _mm512_xor_si512(load(w), flip), x);
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
                let sum = _mm512_reduce_add_epi32(acc).wrapping_sub(correction);
                *y = step.apply(bias.wrapping_add(sum).wrapping_add(tail));
            }
        }
    }
}

/// 64 bytes as a vector.
#[inline]
#[target_feature(enable = "avx512f")]
fn load(bytes: &[u8; LANES]) -> __m512i {
    // SAFETY: `bytes` is 64 bytes long; unaligned loads are allowed.
    #[allow(unsafe_code)]
    unsafe {
        _mm512_loadu_si512(bytes.as_ptr().cast())
    }
}
