//! Features -> head -> pose: the head's layers on the template and source
//! features, its raw i32 outputs, and their conversion to a pose.

use super::{Int8Model, requant};
use crate::arch::{POSE_DIM, ping_pong, prefix};
use crate::error::{Error, Result};
use crate::fixed::OutputStep;
use crate::format::le_f32s;
use crate::format::le_i32s;
use crate::kernel::{
    QValue, Requant, Sink, as_words, bytes_of, dense_tile, dense_vector, dot, rows,
};
use crate::pose::Pose;

impl Int8Model<'_> {
    /// Runs the head on a source feature: returns the output layer's raw
    /// i32 accumulators. `work` needs `2 x` the widest hidden head layer.
    pub fn head(&self, source_feature: &[i8], work: &mut [i8]) -> Result<[i32; POSE_DIM]> {
        Ok(self.head_counted(source_feature, work, None)?.0)
    }

    /// [`Self::head`], also counting the feature entries and hidden head
    /// activations at `i8::MAX` (saturated). With `folded` (the first
    /// layer's biases with its template half added, [`Self::fold_template`]),
    /// a host vector kernel reads only the source half of that layer's
    /// rows; the result is the same, bit for bit.
    pub(super) fn head_counted(
        &self,
        source_feature: &[i8],
        work: &mut [i8],
        folded: Option<&[u8]>,
    ) -> Result<([i32; POSE_DIM], u32)> {
        if !self.has_head() {
            return Err(Error::NoHead);
        }
        let f = self.p.arch.feature_dim();
        let mut saturated = count_saturated(source_feature);
        if source_feature.len() != f {
            return Err(Error::InconsistentDimensions {
                what: "source feature length",
            });
        }
        let half = self.p.arch.widest_hidden_head();
        let (pairs, spare) = work.split_at_mut((2 * half).min(work.len()));
        let (mut a, mut b) = ping_pong(pairs, half)?;
        let expanded = as_words(spare);
        let template = self.p.template_feature;
        // Current input: the concatenation (template, source) for the first
        // layer, then the previous layer's output in `a`.
        let mut len = 0usize;
        for (layer, &width) in self.p.head.iter().zip(self.p.arch.head.iter()) {
            let rq = requant(layer, true);
            let width = width as usize;
            let out = b.get_mut(..width).ok_or(Error::InconsistentDimensions {
                what: "head layer wider than its buffer",
            })?;
            if len == 0 {
                let source = [bytes_of(source_feature)];
                let parts = [template, bytes_of(source_feature)];
                let done = folded.is_some_and(|bias| {
                    let rq = Requant { bias, ..rq };
                    dense_vector(layer.weights, f, &source, rq, expanded, out)
                });
                if !done && !dense_vector(layer.weights, 0, &parts, rq, expanded, out) {
                    let mut sink = Sink::Store {
                        out,
                        outputs: width,
                    };
                    head_first_layer(layer.weights, f, rq, template, source_feature, &mut sink);
                }
            } else {
                let x = prefix(a, len)?;
                if !dense_vector(layer.weights, 0, &[bytes_of(x)], rq, expanded, out) {
                    let mut sink = Sink::Store {
                        out,
                        outputs: width,
                    };
                    dense_tile(layer.weights, len, rq, x, &mut sink);
                }
            }
            len = width;
            saturated += count_saturated(prefix(b, len)?);
            core::mem::swap(&mut a, &mut b);
        }
        let out = &self.p.output;
        let mut raw = [0i32; POSE_DIM];
        let in_dim = if len == 0 { 2 * f } else { len };
        let rows = rows(out.weights, in_dim).zip(le_i32s(out.bias));
        let x = prefix(a, len)?;
        for (r, (row, bias)) in raw.iter_mut().zip(rows) {
            *r = if len == 0 {
                bias.wrapping_add(split_dot(row, template, source_feature))
            } else {
                bias.wrapping_add(dot(row, x))
            };
        }
        Ok((raw, saturated))
    }

    /// Bytes of [`Self::fold_template`]'s biases: an i32 for each output of
    /// the first hidden head layer (0 for a head without one).
    pub(super) fn folded_len(&self) -> usize {
        // Loading checked that the blob has a layer for every hidden width.
        self.p.arch.head.first().map_or(0, |&w| 4 * w as usize)
    }

    /// Writes into `out` ([`Self::folded_len`] bytes, little-endian i32s)
    /// the first hidden head layer's biases with its template half added:
    /// output `o`'s bias plus its first `F` weights times the template
    /// feature (wrapping, as the layer itself adds them). The head then
    /// reads that half of the weights once per model instead of once per
    /// call (`F x F` bytes: 1 MB at the paper's widths). `false`, having
    /// written nothing, when `out` is short or the head has no hidden
    /// layer. (Only the host's vector kernels take the folded biases.)
    #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
    pub(super) fn fold_template(&self, out: &mut [i8]) -> bool {
        let (Some(layer), Some(out)) = (self.p.head.first(), out.get_mut(..self.folded_len()))
        else {
            return false;
        };
        let f = self.p.arch.feature_dim();
        let template = self.p.template_feature;
        let rows = rows(layer.weights, 2 * f).zip(le_i32s(layer.bias));
        for (word, (row, bias)) in out.as_chunks_mut::<4>().0.iter_mut().zip(rows) {
            let (wt, _) = row.split_at(f.min(row.len()));
            *word = bias
                .wrapping_add(dot(wt, template))
                .to_le_bytes()
                .map(|b| b as i8);
        }
        !out.is_empty()
    }

    /// Converts raw head accumulators to reals with the output scales.
    pub fn head_to_real(&self, raw: &[i32; POSE_DIM]) -> [f32; POSE_DIM] {
        let mut out = [0f32; POSE_DIM];
        for ((o, &r), s) in out.iter_mut().zip(raw).zip(le_f32s(self.p.output.scale)) {
            *o = r as f32 * s;
        }
        out
    }

    /// The pose for raw head accumulators.
    pub fn pose(&self, raw: &[i32; POSE_DIM]) -> Result<Pose> {
        Pose::from_head_output(&self.head_to_real(raw))
    }
}

/// Values at `i8::MAX`, the top of the activation range.
pub(super) fn count_saturated(values: &[i8]) -> u32 {
    values.iter().filter(|&&v| v == i8::MAX).count() as u32
}

/// The first head layer: input is `template ++ source`, both F wide, read in place.
fn head_first_layer(
    weights: &[u8],
    f: usize,
    q: Requant<'_>,
    template: &[u8],
    source: &[i8],
    sink: &mut Sink<'_>,
) {
    let rows = rows(weights, 2 * f)
        .zip(le_i32s(q.bias))
        .zip(le_i32s(q.multiplier))
        .zip(q.shift);
    for (o, (((row, bias), m), &s)) in rows.enumerate() {
        let acc = bias.wrapping_add(split_dot(row, template, source));
        let step = OutputStep::new(m, s as i8, q.zero_point, q.act_min);
        sink.take(o, 0, &[acc], &step);
    }
}

/// Dot product of a weight row with the concatenation `a ++ b`.
fn split_dot<A: QValue, B: QValue>(row: &[u8], a: &[A], b: &[B]) -> i32 {
    let (wa, wb) = row.split_at(a.len().min(row.len()));
    dot(wa, a).wrapping_add(dot(wb, b))
}
