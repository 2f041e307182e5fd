//! The host block encoder (`std` feature; x86-64 with AVX2, AVX-VNNI or
//! AVX-512 VNNI, aarch64 with the dot-product extension, see [`Route`]):
//! [`HOST_BLOCK`](crate::arch::HOST_BLOCK) points through every encoder
//! layer, each layer a small matrix product. The aarch64 route (`sdot`)
//! and the AVX-VNNI one (`avxvnni`) are described there; what follows is
//! the AVX2 and AVX-512 VNNI routes.
//!
//! The tile kernel (`super::x86`) multiplies one weight row with eight
//! points' activations along the input axis and must add each point's
//! eight partial sums horizontally, for every output. Here the vector
//! lanes run along the points instead, so no lane sum is ever needed:
//!
//! - the weights of every encoder layer but the pooled one are copied once
//!   per call into int16 rows padded to an even length (input `2j` in the
//!   low half of word `j`, input `2j + 1` in the high half);
//! - a layer's input is kept as int16 pairs *by point*: word `j * BLOCK +
//!   p` holds point `p`'s inputs `2j` and `2j + 1`. The first layer's
//!   input is the coordinates: `(x, y)` then `(z, 0)`;
//! - for two outputs at a time and every input pair (`pairs`), the two
//!   weight words are broadcast and `VPMADDWD` multiplies them with the
//!   pairs of eight points at once (16 multiplies, pairs summed into eight
//!   i32 lanes), half a block (four vectors of points) per weight word at
//!   a time, so the sixteen vectors of work stay in registers; the eight
//!   accumulators start from the biases;
//! - the output step runs on eight points at once, and the two outputs'
//!   activations are interleaved straight into the next layer's pairs; the
//!   last layer keeps each output's largest accumulator over the blocks
//!   ([`raise`]) and its output steps run once, after the last block
//!   (the step is non-decreasing, so that is the max-pool);
//! - the last (pooled) layer, most of the work, runs on bytes instead
//!   when its input is an int8 activation (`bytes`): `VPMADDUBSW` on
//!   the low seven bits of each input, a second pass only for the rare
//!   quads of inputs with the top bit set;
//! - on a CPU with AVX-512 VNNI the layers take another route: the first
//!   (the coordinates, int16) through `wide`, `VPDPWSSD` on the same
//!   pairs, and every later one through `vnni`, `VPDPBUSD` on byte quads
//!   of `x + 128` (64 multiply-adds an instruction, twice `VPDPWSSD`'s),
//!   each layer writing its activations straight into the next one's
//!   quads; sixteen points a vector, four vectors a block, four rows at a
//!   time.
//!
//! Every product and pair sum fits in i32 (`|w| <= 128`, `|x| <= 32767`),
//! and model loading bounds every partial sum (see [`super::dot`]), so the
//! result is the portable kernel's, bit for bit, in any order.

use super::{Requant, as_words, rows, rows_mut};
use crate::arch::{Arch, HOST_BLOCK as BLOCK, INPUT_DIM};
use crate::fixed::OutputStep;
use crate::format::{Int8Layer, le_i32s};
#[cfg(target_arch = "x86_64")]
use area::widen;
use area::{Carved, carve, fill, pair, pooled_on_bytes};

mod area;
#[cfg(target_arch = "x86_64")]
mod avxvnni;
#[cfg(target_arch = "x86_64")]
mod bytes;
#[cfg(target_arch = "x86_64")]
mod pairs;
#[cfg(target_arch = "aarch64")]
#[allow(unsafe_code)]
mod sdot;
#[cfg(target_arch = "x86_64")]
mod vnni;
#[cfg(target_arch = "x86_64")]
mod wide;
#[cfg(target_arch = "x86_64")]
use {
    bytes::pool_bytes,
    pairs::{Dest, layer},
};

/// The kernels a block encoder runs, by what the CPU has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Route {
    /// x86-64 with AVX2: every layer on int16 pairs (`pairs`) but the
    /// pooled one, which runs on bytes (`bytes`) where its input is an
    /// int8 activation.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// x86-64 with AVX-512 VNNI and BW: the first layer on int16 pairs
    /// (`wide`), every later one on byte quads of `x + 128` (`vnni`).
    #[cfg(target_arch = "x86_64")]
    Vnni,
    /// x86-64 with AVX-VNNI but no AVX-512: the same layers on 256-bit
    /// vectors (`avxvnni`).
    #[cfg(target_arch = "x86_64")]
    AvxVnni,
    /// aarch64 with the dot-product extension: the first layer on int16
    /// pairs, every later one on byte quads (`sdot`).
    #[cfg(target_arch = "aarch64")]
    Sdot,
}

/// Whether this CPU has a block kernel (a [`Route`]).
#[cfg(test)]
pub(crate) fn has_route() -> bool {
    Route::detect().is_some()
}

impl Route {
    /// The fastest route this CPU can run, if any.
    fn detect() -> Option<Self> {
        #[cfg(target_arch = "x86_64")]
        {
            if vnni::has_vnni() {
                Some(Route::Vnni)
            } else if avxvnni::has_avxvnni() {
                Some(Route::AvxVnni)
            } else {
                std::is_x86_feature_detected!("avx2").then_some(Route::Avx2)
            }
        }
        #[cfg(target_arch = "aarch64")]
        {
            sdot::has_sdot().then_some(Route::Sdot)
        }
    }

    /// Whether the pooled layer reads its input as byte quads and every
    /// layer after the first does too, with only the first layer's int16
    /// weights copied.
    fn on_quads(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Route::Avx2 => false,
            #[cfg(target_arch = "x86_64")]
            Route::Vnni | Route::AvxVnni => true,
            #[cfg(target_arch = "aarch64")]
            Route::Sdot => true,
        }
    }

    /// Whether layer `l` (0 the first) needs its rows' weight sums: the
    /// byte kernels that hold each input as `x + 128` take `-128 * sum`
    /// into the bias.
    #[cfg_attr(target_arch = "aarch64", allow(unused_variables))]
    fn needs_sums(self, l: usize, layers: usize) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Route::Avx2 => l + 1 == layers && l > 0,
            #[cfg(target_arch = "x86_64")]
            Route::Vnni | Route::AvxVnni => l > 0,
            #[cfg(target_arch = "aarch64")]
            Route::Sdot => false,
        }
    }
}

/// A layer on bytes: its int8 weight rows as stored (`inputs` bytes each)
/// and, where the route needs them ([`Route::needs_sums`]), each row's
/// weight sum.
pub(super) struct ByteLayer<'a> {
    pub weights: &'a [u8],
    pub inputs: usize,
    /// (Read by the x86-64 routes only: the SDOT route is signed.)
    #[cfg_attr(target_arch = "aarch64", allow(dead_code))]
    pub sums: &'a [u32],
}

/// Where a layer's activations go on the quad routes.
pub(super) enum Out<'a> {
    /// The next layer's input as byte quads: word `j * BLOCK + p` holds
    /// point `p`'s activations of outputs `4j..4j + 4` (each plus 128 on
    /// the VNNI route; a missing output past the last reads as activation
    /// 0).
    Quads(&'a mut [u32]),
    /// The max-pool before its output step: each output's largest
    /// accumulator so far (an i32 in each word), to which [`pool_maxima`]
    /// applies the steps once the last block is in ([`raise`]).
    Maxima(&'a mut [u32]),
}

/// A block encoder over a caller's scratch: the int16 weights, the row
/// sums where the route needs them, the pooled layer's quad list when it
/// runs on bytes with AVX2, and two activation buffers.
pub(crate) struct BlockEncoder<'w> {
    weights: &'w [u32],
    /// Each row's weight sum, for every layer after the first in order,
    /// filled where [`Route::needs_sums`] says.
    sums: &'w [u32],
    #[cfg(target_arch = "x86_64")]
    pooled: Option<OnBytes<'w>>,
    /// The pooled layer's largest accumulators over the blocks so far
    /// ([`raise`]), and whether any block has been encoded.
    maxima: &'w mut [u32],
    blocks: bool,
    acts: (&'w mut [u32], &'w mut [u32]),
    route: Route,
}

/// The pooled layer's scratch when it runs on bytes with AVX2.
#[cfg(target_arch = "x86_64")]
struct OnBytes<'w> {
    /// Room for the list of quads that take the high-bit pass.
    quads: &'w mut [u32],
    /// Room for its int16 weights, copied the first time a block has too
    /// many quads with a high bit for the byte kernel to pay (see
    /// [`pool_bytes`]).
    wide: &'w mut [u32],
    widened: bool,
}

impl<'w> BlockEncoder<'w> {
    /// Copies the encoder weights into `area` (at least
    /// [`Arch::host_block_len`] bytes) and returns the encoder; `None`,
    /// having done nothing that matters, on a CPU without a route
    /// ([`Route::detect`]) or without room.
    pub(crate) fn new(arch: &Arch, layers: &[Int8Layer<'_>], area: &'w mut [i8]) -> Option<Self> {
        Self::with_route(arch, layers, area, Route::detect()?)
    }

    /// Copies the encoder weights into `area` as [`Self::new`] does, for
    /// any number of later encoders on it ([`Self::prepared`]); `false`,
    /// having done nothing that matters, where [`Self::new`] gives `None`.
    pub(crate) fn prepare(arch: &Arch, layers: &[Int8Layer<'_>], area: &mut [i8]) -> bool {
        Route::detect().is_some_and(|route| fill(arch, layers, area, route).is_some())
    }

    /// An encoder on an `area` that [`Self::prepare`] filled for these
    /// layers (its weight copies are taken as they stand); `None` where
    /// [`Self::new`] gives `None`.
    pub(crate) fn prepared(arch: &Arch, area: &'w mut [i8]) -> Option<Self> {
        Self::on(arch, area, Route::detect()?)
    }

    /// [`Self::new`] on `route` (which the CPU must be able to run).
    fn with_route(
        arch: &Arch,
        layers: &[Int8Layer<'_>],
        area: &'w mut [i8],
        route: Route,
    ) -> Option<Self> {
        fill(arch, layers, area, route)?;
        Self::on(arch, area, route)
    }

    /// The encoder on an `area` that [`fill`] filled for `route`.
    fn on(arch: &Arch, area: &'w mut [i8], route: Route) -> Option<Self> {
        let Carved {
            weights,
            sums,
            quads,
            maxima,
            a,
            b,
        } = carve(arch, area)?;
        maxima.fill(i32::MIN as u32);
        let sizes = arch.host_block_words();
        // A pooled layer on bytes with AVX2: its int16 weights last, copied
        // when a block first needs them. The quad routes use only the
        // first layer's.
        let on_bytes = pooled_on_bytes(arch, route);
        let later = on_bytes.map_or(0, |shape| shape.pair_words());
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
        let (weights, wide) = weights.split_at_mut_checked(sizes.weights.checked_sub(later)?)?;
        #[cfg(not(target_arch = "x86_64"))]
        let _ = quads;
        Some(BlockEncoder {
            weights,
            sums,
            #[cfg(target_arch = "x86_64")]
            pooled: on_bytes.map(|_| OnBytes {
                quads,
                wide,
                widened: false,
            }),
            maxima,
            blocks: false,
            acts: (a, b),
            route,
        })
    }

    /// Encodes a block of quantized points and max-pools the last layer's
    /// accumulators into the running maxima, which [`Self::pool`] then
    /// takes into a feature. `layers` holds each encoder layer's input and
    /// output widths, int8 weights and requantization, first to last, as
    /// in [`Self::new`].
    pub(crate) fn encode<'q>(
        &mut self,
        points: &[[i16; INPUT_DIM]; BLOCK],
        layers: impl Iterator<Item = (usize, usize, &'q [u8], Requant<'q>)>,
    ) {
        self.blocks = true;
        let (a, b) = (&mut *self.acts.0, &mut *self.acts.1);
        let (xy, z) = a.split_at_mut(BLOCK.min(a.len()));
        for ((xy, z), &[x, y, zc]) in xy.iter_mut().zip(z.iter_mut()).zip(points) {
            *xy = pair(x, y);
            *z = pair(zc, 0);
        }
        let (input, output) = (a, b);
        let (weights, sums, maxima) = (self.weights, self.sums, &mut *self.maxima);
        // SAFETY (every arm): `Route::detect` found what the route's
        // kernels require.
        #[allow(unsafe_code)]
        match self.route {
            #[cfg(target_arch = "x86_64")]
            Route::Vnni => unsafe {
                encode_quads::<vnni::Kernels>(weights, sums, input, output, layers, maxima)
            },
            #[cfg(target_arch = "x86_64")]
            Route::AvxVnni => unsafe {
                encode_quads::<avxvnni::Kernels>(weights, sums, input, output, layers, maxima)
            },
            #[cfg(target_arch = "aarch64")]
            Route::Sdot => unsafe {
                encode_quads::<sdot::Kernels>(weights, sums, input, output, layers, maxima)
            },
            #[cfg(target_arch = "x86_64")]
            Route::Avx2 => unsafe {
                encode_avx2(
                    weights,
                    sums,
                    self.pooled.as_mut(),
                    maxima,
                    input,
                    output,
                    layers,
                )
            },
        }
    }
}

impl BlockEncoder<'_> {
    /// Takes what the blocks left in the running maxima into `feature`,
    /// through the pooled layer's output steps `q`. Call it once the last
    /// block is in.
    pub(crate) fn pool(&self, q: Requant<'_>, feature: &mut [i8]) {
        if self.blocks {
            pool_maxima(self.maxima, q, feature);
        }
    }
}

/// The two kernels of a route on byte quads.
#[allow(unsafe_code)]
trait QuadKernels {
    /// The first layer, on the coordinates as int16 pairs by point:
    /// `weights` holds its rows of `pairs` int16-pair words.
    ///
    /// # Safety
    /// The CPU must have what the route needs.
    unsafe fn first(weights: &[u32], pairs: usize, q: Requant<'_>, input: &[u32], out: Out<'_>);

    /// A later layer, on the previous one's byte quads; `false`, having
    /// written nothing, when `input` is short.
    ///
    /// # Safety
    /// As for [`Self::first`].
    unsafe fn later(layer: &ByteLayer<'_>, q: Requant<'_>, input: &[u32], out: Out<'_>) -> bool;
}

/// [`BlockEncoder::encode`] on a quad route, from the coordinate pairs in
/// `input`: the first layer on them (its int16 `weights`), every later one
/// on the previous one's byte quads (their row `sums` in order, where the
/// route takes them), `output` and `input` taking turns; the pooled
/// layer's largest accumulators into `maxima`.
///
/// # Safety
/// The CPU must have what `K` needs.
#[allow(unsafe_code)]
unsafe fn encode_quads<'a, 'q, K: QuadKernels>(
    weights: &[u32],
    mut sums: &[u32],
    mut input: &'a mut [u32],
    mut output: &'a mut [u32],
    layers: impl Iterator<Item = (usize, usize, &'q [u8], Requant<'q>)>,
    maxima: &mut [u32],
) {
    let mut layers = layers.peekable();
    let mut first = true;
    while let Some((inputs, outputs, bytes, q)) = layers.next() {
        let out = if layers.peek().is_none() {
            Out::Maxima(&mut *maxima)
        } else {
            Out::Quads(&mut *output)
        };
        if core::mem::take(&mut first) {
            let w = weights.get(..outputs * inputs.div_ceil(2)).unwrap_or(&[]);
            // SAFETY: the caller's.
            unsafe { K::first(w, inputs.div_ceil(2), q, input, out) };
        } else {
            let (s, rest) = sums.split_at(sums.len().min(outputs));
            sums = rest;
            let layer = ByteLayer {
                weights: bytes,
                inputs,
                sums: s,
            };
            // SAFETY: the caller's.
            if !unsafe { K::later(&layer, q, input, out) } {
                return;
            }
        }
        core::mem::swap(&mut input, &mut output);
    }
}

/// [`BlockEncoder::encode`] on the AVX2 route, from the coordinate pairs
/// in `input`: every layer on int16 pairs ([`layer`], their `weights` in
/// order) but a pooled layer on bytes (`pooled`, its row sums the last of
/// `sums`), `output` and `input` taking turns.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
unsafe fn encode_avx2<'a, 'q>(
    mut weights: &[u32],
    sums: &[u32],
    mut pooled: Option<&mut OnBytes<'_>>,
    maxima: &mut [u32],
    mut input: &'a mut [u32],
    mut output: &'a mut [u32],
    layers: impl Iterator<Item = (usize, usize, &'q [u8], Requant<'q>)>,
) {
    let mut layers = layers.peekable();
    while let Some((inputs, outputs, bytes, q)) = layers.next() {
        let pairs = inputs.div_ceil(2);
        let last = layers.peek().is_none();
        if let (true, Some(on)) = (last, pooled.as_mut()) {
            let layer_on_bytes = ByteLayer {
                weights: bytes,
                inputs,
                // The pooled layer's sums are the last.
                sums: sums
                    .get(sums.len().saturating_sub(outputs)..)
                    .unwrap_or(&[]),
            };
            // SAFETY: the caller's (AVX2, all `pool_bytes` and `layer`
            // require).
            unsafe {
                if !pool_bytes(&layer_on_bytes, q, input, output, on.quads, maxima) {
                    if !on.widened {
                        widen(bytes, inputs, on.wide);
                        on.widened = true;
                    }
                    layer(on.wide, pairs, q, input, Dest::Maxima(maxima));
                }
            };
            return;
        }
        let (w, rest) = weights.split_at(weights.len().min(outputs * pairs));
        weights = rest;
        let dest = if last {
            Dest::Maxima(&mut *maxima)
        } else {
            Dest::Pairs(&mut *output)
        };
        // SAFETY: the caller's.
        unsafe { layer(w, pairs, q, input, dest) };
        core::mem::swap(&mut input, &mut output);
    }
}

/// Rows a group of the quad routes' kernels takes together, sharing each
/// load of the block's inputs (four outputs fill a quad of the next
/// layer's input).
const ROWS: usize = 4;

/// Rows `o..o + ROWS` of a layer with `outputs` rows of `len` values in
/// `weights`: each row, its bias (less `128` times the row's weight sum
/// where `sums` has them, for inputs held as `x + 128`) and its output
/// step. Missing rows (past the last) repeat the last with a zero bias and
/// no step; their results are never taken.
#[allow(clippy::type_complexity)]
#[inline(always)]
fn group<'a, T>(
    weights: &'a [T],
    len: usize,
    q: Requant<'_>,
    o: usize,
    outputs: usize,
    sums: &[u32],
) -> ([&'a [T]; ROWS], [i32; ROWS], [Option<OutputStep>; ROWS]) {
    let n = outputs.saturating_sub(o).clamp(1, ROWS);
    let (bias, mult) = (q.bias.as_chunks::<4>().0, q.multiplier.as_chunks::<4>().0);
    let (mut rs, mut biases, mut steps) = ([&[][..]; ROWS], [0; ROWS], [None; ROWS]);
    for (r, ((row, b), step)) in rs.iter_mut().zip(&mut biases).zip(&mut steps).enumerate() {
        let ch = o + r.min(n - 1);
        *row = weights.get(ch * len..(ch + 1) * len).unwrap_or(&[]);
        if let (true, Some(&bias), Some(&m), Some(&s)) =
            (r < n, bias.get(ch), mult.get(ch), q.shift.get(ch))
        {
            let sum = sums.get(ch).map_or(0, |&s| s as i32);
            *b = i32::from_le_bytes(bias).wrapping_sub(sum.wrapping_mul(128));
            *step = Some(OutputStep::new(
                i32::from_le_bytes(m),
                s as i8,
                q.zero_point,
                q.act_min,
            ));
        }
    }
    (rs, biases, steps)
}

/// Weights `4j..4j + 4` of a row as one word, zeros past its end.
#[inline]
fn quad(row: &[u8], j: usize) -> i32 {
    let mut word = [0u8; 4];
    for (w, &v) in word.iter_mut().zip(row.iter().skip(4 * j)) {
        *w = v;
    }
    i32::from_le_bytes(word)
}

/// Raises output `o`'s running maximum (an i32 in each word of `maxima`,
/// `i32::MIN` at first) to `acc`. The pooled layer keeps its largest
/// accumulators over the blocks and [`pool_maxima`] applies the output
/// steps once the last block is in: the step is non-decreasing (see
/// [`Sink::Pool`](super::Sink::Pool)), so the step of the largest accumulator is the largest
/// activation, and one step per output replaces one per output and block.
#[inline]
fn raise(maxima: &mut [u32], o: usize, acc: i32) {
    if let Some(slot) = maxima.get_mut(o)
        && acc > *slot as i32
    {
        *slot = acc as u32;
    }
}

/// Applies the pooled layer's output steps to the largest accumulators
/// that the blocks left in `maxima` and raises `feature` to each
/// activation.
fn pool_maxima(maxima: &[u32], q: Requant<'_>, feature: &mut [i8]) {
    let steps = le_i32s(q.multiplier).zip(q.shift);
    for ((f, &acc), (m, &s)) in feature.iter_mut().zip(maxima).zip(steps) {
        let v = OutputStep::new(m, s as i8, q.zero_point, q.act_min).apply(acc as i32);
        *f = (*f).max(v);
    }
}

#[cfg(test)]
pub(super) mod tests;
