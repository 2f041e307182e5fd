//! The block kernel's first layer with AVX-512 VNNI (`VPDPWSSD`): its
//! input is the coordinates as int16 pairs, not int8 activations, so it
//! cannot take [`super::vnni::layer_bytes`]'s byte quads.

use core::arch::x86_64::{__m512i, _mm512_dpwssd_epi32, _mm512_set1_epi32, _mm512_setzero_si512};

use super::super::{Requant, rows};
use super::BLOCK;
use super::vnni::{WIDE, block_vectors, finish};
use super::{Out, ROWS, group};

/// A layer on int16 pairs with AVX-512 VNNI: `weights` holds `outputs`
/// rows of `pairs` int16-pair words, `input` the block's input pairs by
/// point (as [`super::layer`]'s). `VPDPWSSD` multiplies each point's input
/// pair with a broadcast weight pair and adds both products to the point's
/// i32 accumulator in one instruction (no saturation), sixteen points a
/// vector, four vectors a block, four rows sharing each load; the
/// activations go to `out` as [`finish`] takes them. The sums are the
/// portable kernel's exact integers (`|w| <= 128`, `|x| <= 32767`), so the
/// results are its bits.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) fn layer_wide(
    weights: &[u32],
    pairs: usize,
    q: Requant<'_>,
    input: &[u32],
    mut out: Out<'_>,
) {
    let Some(input) = input.get(..pairs * BLOCK) else {
        return;
    };
    let outputs = q.bias.len() / 4;
    for o in (0..outputs).step_by(ROWS) {
        let (rs, biases, steps) = group(weights, pairs, q, o, outputs, &[]);
        let mut acc = [[_mm512_setzero_si512(); WIDE]; ROWS];
        for (acc, b) in acc.iter_mut().zip(biases) {
            *acc = [_mm512_set1_epi32(b); WIDE];
        }
        // (Plain loops: a closure would not inherit the target features,
        // and its intrinsics would become calls.)
        let [r0, r1, r2, r3] = rs;
        let columns = r0.iter().zip(r1).zip(r2).zip(r3);
        for ((((&a, &b), &c), &d), x) in columns.zip(rows(input, BLOCK)) {
            pair_step(&mut acc, [a, b, c, d], x);
        }
        finish(acc, &steps, o, &mut out);
    }
}

/// Adds to `ROWS` rows' accumulators over the block the products of their
/// weight pairs `w` with the input pairs `x` (one word per point).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
fn pair_step(acc: &mut [[__m512i; WIDE]; ROWS], w: [u32; ROWS], x: &[u32]) {
    let Some(xs) = block_vectors(x) else {
        return;
    };
    for (acc, &w) in acc.iter_mut().zip(&w) {
        let w = _mm512_set1_epi32(w as i32);
        for (a, &x) in acc.iter_mut().zip(&xs) {
            *a = _mm512_dpwssd_epi32(*a, x, w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::test_layer::block_cases;
    use super::super::area::widen;
    use super::super::tests::{check_layer, pairs_by_point};
    use super::super::vnni::tests::vnni;
    use super::*;

    /// `layer_wide` gives the portable kernel's activations, stored as
    /// byte quads and max-pooled, on every case of [`block_cases`] (their
    /// int8 inputs as int16 pairs).
    #[test]
    fn wide_layer_matches_portable() {
        if !vnni() {
            return;
        }
        for c in block_cases(39) {
            let (q, pairs) = (c.layer.requant(), c.inputs.div_ceil(2));
            let mut wide = std::vec![0u32; c.outputs * pairs];
            widen(&c.layer.weights, c.inputs, &mut wide);
            let input = pairs_by_point(&c.x, c.inputs);
            // SAFETY: the CPU has AVX-512 VNNI and BW (checked above).
            #[allow(unsafe_code)]
            check_layer(&c, "wide", 0x80, &|out| unsafe {
                layer_wide(&wide, pairs, q, &input, out)
            });
        }
    }
}
