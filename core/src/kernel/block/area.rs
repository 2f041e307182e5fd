//! A block encoder's scratch: how [`Arch::host_block_words`] lays it out,
//! and the weight copies and row sums written into it once per model (or
//! per call, see [`BlockEncoder::new`](super::BlockEncoder::new) and
//! [`BlockEncoder::prepare`](super::BlockEncoder::prepare)).

use super::{Route, as_words, rows, rows_mut};
use crate::arch::{Arch, LayerShape};
use crate::format::Int8Layer;

/// The parts of a block encoder's area (see [`Arch::host_block_words`]).
pub(super) struct Carved<'w> {
    pub(super) weights: &'w mut [u32],
    pub(super) sums: &'w mut [u32],
    pub(super) quads: &'w mut [u32],
    pub(super) maxima: &'w mut [u32],
    pub(super) a: &'w mut [u32],
    pub(super) b: &'w mut [u32],
}

/// Cuts a block encoder's `area` (at least [`Arch::host_block_len`]
/// bytes) into its parts; `None` when it is short.
pub(super) fn carve<'w>(arch: &Arch, area: &'w mut [i8]) -> Option<Carved<'w>> {
    if area.len() < arch.host_block_len() {
        return None;
    }
    let sizes = arch.host_block_words();
    let words = as_words(area);
    let (weights, rest) = words.split_at_mut_checked(sizes.weights)?;
    let (sums, rest) = rest.split_at_mut_checked(sizes.sums)?;
    let (quads, rest) = rest.split_at_mut_checked(sizes.quads)?;
    let (maxima, rest) = rest.split_at_mut_checked(sizes.maxima)?;
    let (a, rest) = rest.split_at_mut_checked(sizes.buffer)?;
    let b = rest.get_mut(..sizes.buffer)?;
    Some(Carved {
        weights,
        sums,
        quads,
        maxima,
        a,
        b,
    })
}

/// Writes what `route` reads of the weights into a block encoder's
/// `area`: each row's weight sum where [`Route::needs_sums`] says, and the
/// int16 rows of the layers it runs on pairs (all but a pooled layer on
/// bytes with AVX2, which is widened only if a block needs it; only the
/// first on the quad routes). `None` when the area is short.
pub(super) fn fill(
    arch: &Arch,
    layers: &[Int8Layer<'_>],
    area: &mut [i8],
    route: Route,
) -> Option<()> {
    let Carved { weights, sums, .. } = carve(arch, area)?;
    let count = arch.encoder.len();
    let mut free = sums;
    for (l, (shape, layer)) in arch.encoder_layers().zip(layers).enumerate().skip(1) {
        let (out, tail) = free.split_at_mut_checked(shape.outputs)?;
        if route.needs_sums(l, count) {
            for (sum, row) in out.iter_mut().zip(rows(layer.weights, shape.inputs)) {
                *sum = row_sum(row);
            }
        }
        free = tail;
    }
    let widened = if route.on_quads() {
        1
    } else {
        count.saturating_sub(usize::from(pooled_on_bytes(arch, route).is_some()))
    };
    let mut free = weights;
    for (shape, layer) in arch.encoder_layers().zip(layers).take(widened) {
        let (out, tail) = free.split_at_mut_checked(shape.pair_words())?;
        widen(layer.weights, shape.inputs, out);
        free = tail;
    }
    Some(())
}

/// The pooled layer's shape when `route` runs it on bytes (AVX2, its input
/// an int8 activation): its int16 weights come last in the area and are
/// copied only when a block needs them. `None` on the quad routes, or when
/// the pooled layer reads the coordinates.
pub(super) fn pooled_on_bytes(arch: &Arch, route: Route) -> Option<LayerShape> {
    let quads = arch.host_block_words().quads;
    let last = arch.encoder_layers().last();
    last.filter(|_| quads > 0 && !route.on_quads())
}

/// Sign-extends a layer's int8 weight rows of `inputs` values into int16
/// pair words, each row padded with a zero to an even length.
pub(super) fn widen(weights: &[u8], inputs: usize, out: &mut [u32]) {
    let pairs = inputs.div_ceil(2);
    for (row, out) in rows(weights, inputs).zip(rows_mut(out, pairs)) {
        for (j, word) in out.iter_mut().enumerate() {
            let w = |k: usize| row.get(k).map_or(0, |&b| b as i8 as i16);
            *word = pair(w(2 * j), w(2 * j + 1));
        }
    }
}

/// Two int16 values as one word, `lo` in the low half.
pub(super) fn pair(lo: i16, hi: i16) -> u32 {
    (lo as u16 as u32) | ((hi as u16 as u32) << 16)
}

/// The sum of an int8 weight row (as a word), which the byte kernels that
/// hold each input as `x + 128` take `-128` times into the bias.
pub(super) fn row_sum(row: &[u8]) -> u32 {
    row.iter().map(|&w| w as i8 as i32).sum::<i32>() as u32
}
