//! The int8 dense kernel, used by every quantized layer.

use crate::fixed::OutputStep;
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

/// The first `n` values (all of them if there are fewer): `split_at` at a
/// clamped index, which leaves no bounds check behind at any optimisation level.
#[cfg(pcrnet_arm_dsp)]
#[inline(always)]
fn prefix_of<T>(values: &[T], n: usize) -> &[T] {
    values.split_at(n.min(values.len())).0
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
    let (w, a, b) = (prefix_of(w, n), prefix_of(a, n), prefix_of(b, n));
    let (wc, ac, bc) = (w.chunks_exact(4), a.chunks_exact(4), b.chunks_exact(4));
    let tail_a = scalar_dot(wc.remainder(), ac.remainder());
    let tail_b = scalar_dot(wc.remainder(), bc.remainder());
    let (mut acc_a, mut acc_b) = (0i32, 0i32);
    for ((w4, a4), b4) in wc.zip(ac).zip(bc) {
        // Chunks of four: the patterns always match (no bounds checks).
        let (&[w0, w1, w2, w3], &[a0, a1, a2, a3], &[b0, b1, b2, b3]) = (w4, a4, b4) else {
            continue;
        };
        let wv = u32::from_le_bytes([w0, w1, w2, w3]);
        let av = u32::from_le_bytes([a0 as u8, a1 as u8, a2 as u8, a3 as u8]);
        let bv = u32::from_le_bytes([b0 as u8, b1 as u8, b2 as u8, b3 as u8]);
        let (we, wo) = (dsp::sxtb16(wv), dsp::sxtb16_ror8(wv));
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
    let (w, x) = (prefix_of(w, n), prefix_of(x, n));
    let (wc, xc) = (w.chunks_exact(4), x.chunks_exact(4));
    let tail = scalar_dot(wc.remainder(), xc.remainder());
    let mut acc = 0i32;
    for (w4, x4) in wc.zip(xc) {
        // Chunks of four: the patterns always match (no bounds checks).
        let (&[w0, w1, w2, w3], &[x0, x1, x2, x3]) = (w4, x4) else {
            continue;
        };
        let wv = u32::from_le_bytes([w0, w1, w2, w3]);
        let xv = u32::from_le_bytes([byte(x0), byte(x1), byte(x2), byte(x3)]);
        acc = dsp::smlad(dsp::sxtb16(wv), dsp::sxtb16(xv), acc);
        acc = dsp::smlad(dsp::sxtb16_ror8(wv), dsp::sxtb16_ror8(xv), acc);
    }
    acc.wrapping_add(tail)
}

#[cfg(pcrnet_arm_dsp)]
#[allow(unsafe_code)]
pub(crate) mod dsp;

#[cfg(all(target_arch = "x86_64", feature = "std"))]
mod x86;

#[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
pub(crate) mod block;

#[cfg(all(target_arch = "aarch64", feature = "std"))]
#[allow(unsafe_code)]
mod neon;

#[cfg(all(
    test,
    any(target_arch = "x86_64", target_arch = "aarch64"),
    feature = "std"
))]
mod test_layer;

/// int8 values as the bytes they are stored in.
pub(crate) fn bytes_of(x: &[i8]) -> &[u8] {
    // SAFETY: i8 and u8 have the same size and alignment, and every bit
    // pattern is valid for both; the slice keeps `x`'s lifetime.
    #[allow(unsafe_code)]
    unsafe {
        core::slice::from_raw_parts(x.as_ptr() as *const u8, x.len())
    }
}

/// The bytes of `words`, as int8 values.
#[cfg(all(target_arch = "aarch64", feature = "std"))]
pub(crate) fn as_bytes(words: &mut [u32]) -> &mut [i8] {
    // SAFETY: i8 needs no alignment and every bit pattern is a valid i8
    // and u32; `align_to_mut` hands out all of `words` as the middle part,
    // with its lifetime.
    #[allow(unsafe_code)]
    let (_, bytes, _) = unsafe { words.align_to_mut::<i8>() };
    bytes
}

/// Views the scratch bytes left for expanded activations as aligned `u32`
/// words (the DSP kernel loads them with `LDM`, which needs alignment).
pub(crate) fn as_words(bytes: &mut [i8]) -> &mut [u32] {
    // SAFETY: every bit pattern is a valid u32 and a valid i8, and
    // `align_to_mut` only hands out the correctly aligned middle part.
    #[allow(unsafe_code)]
    let (_, words, _) = unsafe { bytes.align_to_mut::<u32>() };
    words
}

/// The rows of a weight matrix (or of a tile) of `len` values each. A
/// layer's lengths are validated at load and never 0; the branch shows
/// the compiler that `chunks_exact` is never asked for empty chunks, so
/// no panic path is left (`len.max(1)` is not enough for LLVM).
#[inline(always)]
pub(crate) fn rows<T>(values: &[T], len: usize) -> core::slice::ChunksExact<'_, T> {
    match core::num::NonZeroUsize::new(len) {
        Some(len) => values.chunks_exact(len.get()),
        None => values.chunks_exact(1),
    }
}

/// One output of a dense layer on a vector: its bias, its output step and
/// where its activation goes.
#[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
pub(crate) type Channel<'a> = (i32, OutputStep, &'a mut i8);

/// A dense layer on one vector taken four outputs at a time (the host's
/// vector kernels): each group's four weight rows of `inputs` bytes and its
/// outputs. Each row of `weights` is `skip + inputs` bytes, of which the
/// first `skip` are left out (see [`dense_vector`]). A group past the last
/// output reads the group's first row again in its place, with no output,
/// so a kernel can always run four rows.
#[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
pub(crate) fn row_groups<'a>(
    weights: &'a [u8],
    skip: usize,
    inputs: usize,
    q: Requant<'a>,
    out: &'a mut [i8],
) -> impl Iterator<Item = ([&'a [u8]; 4], [Option<Channel<'a>>; 4])> {
    let params = le_i32s(q.bias).zip(le_i32s(q.multiplier)).zip(q.shift);
    let rows = rows(weights, skip + inputs).map(move |row| row.get(skip..).unwrap_or(&[]));
    let mut channels =
        rows.zip(params)
            .zip(out.iter_mut())
            .map(move |((row, ((bias, m), &s)), y)| {
                let step = OutputStep::new(m, s as i8, q.zero_point, q.act_min);
                (row, (bias, step, y))
            });
    core::iter::from_fn(move || {
        let group: [_; 4] = core::array::from_fn(|_| channels.next());
        let first = group[0].as_ref()?.0;
        let rows = group
            .each_ref()
            .map(|g| g.as_ref().map_or(first, |(r, _)| *r));
        Some((rows, group.map(|g| g.map(|(_, channel)| channel))))
    })
}

/// [`rows`] for a mutable slice.
#[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
#[inline(always)]
pub(crate) fn rows_mut<T>(values: &mut [T], len: usize) -> core::slice::ChunksExactMut<'_, T> {
    match core::num::NonZeroUsize::new(len) {
        Some(len) => values.chunks_exact_mut(len.get()),
        None => values.chunks_exact_mut(1),
    }
}

/// One dense layer with int8 inputs over a tile of rows: [`dense_tile`]'s
/// contract and results (bit for bit). On thumbv7em, rows go through the
/// DSP kernel four at a time (`dsp::dot4`) when `inputs` is a multiple of
/// 4 and `expanded` holds their int16 activations (`2 x inputs` words per
/// group of four rows, see `arch::expanded_len`). On x86-64 with the `std`
/// feature, a full tile of at least 16 inputs goes through the AVX2
/// kernel (`x86`) when the CPU has AVX2; on aarch64 with the `std`
/// feature, through the NEON kernel (`neon`: `SDOT` where the CPU has it).
/// Other rows and targets take [`dense_tile`]'s path.
#[inline(always)]
pub(crate) fn dense_tile_i8(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[i8],
    expanded: &mut [u32],
    sink: &mut Sink<'_>,
) {
    #[cfg(pcrnet_arm_dsp)]
    {
        use dsp::QUAD;
        let per_quad = QUAD * inputs / 2;
        let points = x.len().checked_div(inputs).unwrap_or(0);
        let quads = (points / QUAD).min(expanded.len() / per_quad.max(1));
        if inputs.is_multiple_of(4)
            && inputs > 0
            && quads > 0
            && let Some((head, rest)) = x.split_at_checked(quads * QUAD * inputs)
            && let Some(expanded) = expanded.get_mut(..quads * per_quad)
        {
            for (quad, out) in
                rows(head, QUAD * inputs).zip(expanded.chunks_exact_mut(per_quad.max(1)))
            {
                dsp::expand_quad(quad, inputs, out);
            }
            let params = le_i32s(q.bias).zip(le_i32s(q.multiplier)).zip(q.shift);
            let quad_acts = rows(expanded, per_quad);
            for (o, (row, ((bias, m), &s))) in rows(weights, inputs).zip(params).enumerate() {
                let step = OutputStep::new(m, s as i8, q.zero_point, q.act_min);
                for (k, quad) in quad_acts.clone().enumerate() {
                    sink.take(o, QUAD * k, &dsp::dot4(row, quad, bias), &step);
                }
            }
            dense_tile_from(weights, inputs, q, rest, quads * QUAD, sink);
            return;
        }
    }
    #[cfg(all(target_arch = "x86_64", feature = "std"))]
    if x86::dense_tile(weights, inputs, q, x, expanded, sink) {
        return;
    }
    #[cfg(all(target_arch = "aarch64", feature = "std"))]
    if neon::dense_tile(weights, inputs, q, x, sink) {
        return;
    }
    let _ = expanded;
    dense_tile(weights, inputs, q, x, sink)
}

/// The first encoder layer: `points` holds the tile's int16 coordinates,
/// three per point (`x y z`). [`dense_tile`]'s contract and results (bit for
/// bit) for three inputs, with the per-output work done once per output
/// and tile: the three weights, the bias and the output step are read
/// once, then each point costs three multiply-adds. On x86-64 with the
/// `std` feature, a full tile goes through the AVX2 kernel (`x86`) when
/// the CPU has AVX2.
#[inline(always)]
pub(crate) fn dense_points(weights: &[u8], q: Requant<'_>, points: &[i16], sink: &mut Sink<'_>) {
    #[cfg(all(target_arch = "x86_64", feature = "std"))]
    if x86::dense_points(weights, q, points, sink) {
        return;
    }
    portable_points(weights, q, points, sink)
}

/// [`dense_points`] on every target: the portable loop.
#[inline(always)]
fn portable_points(weights: &[u8], q: Requant<'_>, points: &[i16], sink: &mut Sink<'_>) {
    const DIM: usize = crate::arch::INPUT_DIM;
    const MAX: usize = crate::arch::MAX_TILE;
    let rows = weights
        .as_chunks::<DIM>()
        .0
        .iter()
        .zip(le_i32s(q.bias))
        .zip(le_i32s(q.multiplier))
        .zip(q.shift);
    for (o, (((row, bias), m), &s)) in rows.enumerate() {
        let step = OutputStep::new(m, s as i8, q.zero_point, q.act_min);
        let [w0, w1, w2] = row.map(|w| w as i8 as i32);
        for (c, chunk) in points.chunks(DIM * MAX).enumerate() {
            let mut accs = [0i32; MAX];
            let mut n = 0;
            for (acc, p) in accs.iter_mut().zip(chunk.as_chunks::<DIM>().0) {
                let &[x, y, z] = p;
                *acc = bias.wrapping_add(w0 * x as i32 + w1 * y as i32 + w2 * z as i32);
                n += 1;
            }
            let (accs, _) = accs.split_at(n.min(MAX));
            sink.take(o, c * MAX, accs, &step);
        }
    }
}

/// A dense layer on one vector, the concatenation of `parts` (int8 values
/// as bytes; the head's first layer reads the template feature from the
/// blob and the source feature from scratch): `out[o]` gets output `o`'s
/// activation, as [`dense_tile`] on the concatenated vector would give it
/// (bit for bit). Returns `false`, having done nothing, where no kernel
/// applies: on targets with neither kernel below, or where the kernel's
/// conditions are not met (then [`dense_tile`] runs on the vector).
///
/// Each row of `weights` is `skip` bytes and then one weight per input:
/// the first `skip` weights of every row are left out, their products with
/// a constant part of the input being in `q`'s biases already (the head's
/// template half, folded by [`crate::Int8Model::prepare`]). Only the host
/// kernels take a `skip` other than 0.
///
/// On thumbv7em (parts of multiples of 4, `expanded` holding the vector's
/// `inputs / 2` words) the vector is expanded to int16 pairs once and four
/// weight rows share each pair of activation words (`dsp::dot_rows4`). On
/// x86-64 with the `std` feature and AVX2 (at least 16 inputs) the AVX2
/// kernel runs, four rows at a time (`x86::dense_vector`); on aarch64 with
/// the `std` feature (at least 16 inputs), the NEON kernel
/// (`neon::dense_vector`).
#[inline(always)]
pub(crate) fn dense_vector(
    weights: &[u8],
    skip: usize,
    parts: &[&[u8]],
    q: Requant<'_>,
    expanded: &mut [u32],
    out: &mut [i8],
) -> bool {
    #[cfg(pcrnet_arm_dsp)]
    {
        let inputs: usize = parts.iter().map(|p| p.len()).sum();
        let words = inputs / 2;
        if skip != 0
            || inputs == 0
            || parts.iter().any(|p| !p.len().is_multiple_of(4))
            || expanded.len() < words
        {
            return false;
        }
        let Some(acts) = expanded.get_mut(..words) else {
            return false;
        };
        let mut free = &mut *acts;
        for part in parts {
            let Some((out, rest)) = free.split_at_mut_checked(part.len() / 2) else {
                return false;
            };
            dsp::expand_vector(part, out);
            free = rest;
        }
        let acts = &*acts;
        // Four rows, with their four biases, multipliers and shifts.
        // Four rows, with their four biases, multipliers, shifts and outputs.
        let (quads, last) = out.as_chunks_mut::<4>();
        let groups = rows(weights, 4 * inputs)
            .zip(q.bias.as_chunks::<16>().0)
            .zip(q.multiplier.as_chunks::<16>().0)
            .zip(q.shift.as_chunks::<4>().0)
            .zip(quads);
        let mut o = 0;
        for ((((rows, bias), m), shift), y) in groups {
            let accs = dsp::dot_rows4(rows, inputs, acts, words4(bias));
            for (((y, acc), m), &s) in y.iter_mut().zip(accs).zip(words4(m)).zip(shift) {
                *y = OutputStep::new(m, s as i8, q.zero_point, q.act_min).apply(acc);
            }
            o += 4;
        }
        // The last rows (fewer than four), one at a time.
        let rest = rows(weights, inputs)
            .zip(le_i32s(q.bias))
            .zip(le_i32s(q.multiplier))
            .zip(q.shift)
            .skip(o)
            .zip(last);
        for ((((row, b), m), &s), y) in rest {
            let mut acc = b;
            let mut row = row;
            for part in parts {
                let (w, tail) = row.split_at(part.len().min(row.len()));
                acc = acc.wrapping_add(dot(w, part));
                row = tail;
            }
            *y = OutputStep::new(m, s as i8, q.zero_point, q.act_min).apply(acc);
        }
        true
    }
    #[cfg(all(target_arch = "x86_64", feature = "std"))]
    {
        x86::dense_vector(weights, skip, parts, q, expanded, out)
    }
    #[cfg(all(target_arch = "aarch64", feature = "std"))]
    {
        neon::dense_vector(weights, skip, parts, q, expanded, out)
    }
    #[cfg(not(any(
        pcrnet_arm_dsp,
        all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std")
    )))]
    {
        let _ = (weights, skip, parts, q, expanded, out);
        false
    }
}

/// Four little-endian i32 from 16 bytes (destructured: no bounds check).
#[cfg(pcrnet_arm_dsp)]
#[inline(always)]
fn words4(b: &[u8; 16]) -> [i32; 4] {
    let [
        a0,
        a1,
        a2,
        a3,
        b0,
        b1,
        b2,
        b3,
        c0,
        c1,
        c2,
        c3,
        d0,
        d1,
        d2,
        d3,
    ] = *b;
    [
        i32::from_le_bytes([a0, a1, a2, a3]),
        i32::from_le_bytes([b0, b1, b2, b3]),
        i32::from_le_bytes([c0, c1, c2, c3]),
        i32::from_le_bytes([d0, d1, d2, d3]),
    ]
}

/// Where a layer's int8 activations go.
pub(crate) enum Sink<'a> {
    /// Row `t`'s activation of output `o` is stored at `out[t * outputs + o]`.
    Store {
        /// The next layer's input tile.
        out: &'a mut [i8],
        /// Values per row.
        outputs: usize,
    },
    /// Max-pool over rows: `feature[o] = max(feature[o], activation)`.
    ///
    /// The output step is non-decreasing in the accumulator (model loading
    /// rejects negative multipliers, and rounding, the zero point and the
    /// clamp all preserve order), so the largest activation over rows is
    /// the activation of the largest accumulator: one output step per
    /// output and group of rows instead of one per row, same bits.
    Pool(&'a mut [i8]),
}

impl Sink<'_> {
    /// Takes the accumulators of output `o` for rows `first..first +
    /// accs.len()`.
    #[inline(always)]
    pub(crate) fn take(&mut self, o: usize, first: usize, accs: &[i32], step: &OutputStep) {
        match self {
            Sink::Store { out, outputs } => {
                for (j, &acc) in accs.iter().enumerate() {
                    if let Some(y) = out.get_mut((first + j) * *outputs + o) {
                        *y = step.apply(acc);
                    }
                }
            }
            Sink::Pool(feature) => {
                if let (Some(&acc), Some(f)) = (accs.iter().max(), feature.get_mut(o)) {
                    let v = step.apply(acc);
                    if v > *f {
                        *f = v;
                    }
                }
            }
        }
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
/// is read once per tile) and row `t`, the int8 activation goes to `sink`.
/// Only the first `x.len() / inputs` rows are processed.
#[inline(always)]
pub(crate) fn dense_tile<X: QValue>(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[X],
    sink: &mut Sink<'_>,
) {
    dense_tile_from(weights, inputs, q, x, 0, sink)
}

/// [`dense_tile`] for rows numbered from `first`.
#[inline(always)]
fn dense_tile_from<X: QValue>(
    weights: &[u8],
    inputs: usize,
    q: Requant<'_>,
    x: &[X],
    first: usize,
    sink: &mut Sink<'_>,
) {
    if x.len() < inputs.max(1) {
        return;
    }
    let channels = rows(weights, inputs)
        .zip(le_i32s(q.bias))
        .zip(le_i32s(q.multiplier))
        .zip(q.shift);
    for (o, (((row, bias), m), &s)) in channels.enumerate() {
        let step = OutputStep::new(m, s as i8, q.zero_point, q.act_min);
        // Two rows at a time share each weight load (see `dot2`).
        let mut pairs = rows(x, 2 * inputs);
        let mut t = first;
        for pair in pairs.by_ref() {
            let (a, b) = pair.split_at(pair.len() / 2);
            let (da, db) = X::dot2(row, a, b);
            sink.take(o, t, &[bias.wrapping_add(da), bias.wrapping_add(db)], &step);
            t += 2;
        }
        let rest = pairs.remainder();
        if rest.len() == inputs {
            sink.take(o, t, &[bias.wrapping_add(dot(row, rest))], &step);
        }
    }
}
