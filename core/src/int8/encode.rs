//! Points -> quantize -> encode: the int16 input grid, the encoder's
//! layers tile by tile (or block by block on an x86-64 host), and the
//! max-pool into the global feature.

use super::{Int8Model, Ready, requant};
use crate::arch::{INPUT_DIM, MAX_TILE, ping_pong, prefix};
use crate::error::{Error, Result};
use crate::fixed::quantize_coordinate;
use crate::kernel::{Sink, as_words, dense_points, dense_tile_i8};
use crate::pose::PointMap;
use crate::registration::Sample;
#[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
use crate::{arch::HOST_BLOCK, kernel::Requant, kernel::block::BlockEncoder};

/// Points collected before they go through the encoder: a host block
/// where the block kernel exists, a tile elsewhere.
#[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
const COLLECT: usize = HOST_BLOCK;
#[cfg(not(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std")))]
const COLLECT: usize = MAX_TILE;

impl Int8Model<'_> {
    /// Quantizes point `index` to the model's int16 input grid, after
    /// moving it by `map` (into the model frame, then by the current pose);
    /// `None` if it lies outside the input range (a moved point may leave
    /// it). A non-finite coordinate is an error.
    pub fn quantize_point(
        &self,
        index: usize,
        p: &[f32; 3],
        map: &PointMap,
    ) -> Result<Option<[i16; 3]>> {
        if p.iter().any(|x| !x.is_finite()) {
            return Err(Error::NonFiniteCoordinate { index });
        }
        let [x, y, z] = map.apply(*p);
        let q = |v| quantize_coordinate(v, self.p.input_scale);
        Ok(match (q(x), q(y), q(z)) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            _ => None,
        })
    }

    /// Encodes `sample`, each point first moved by `map`, into `feature`
    /// (max-pooled over the points). Points outside the input range are
    /// left out; returns how many. Those inside are packed into tiles of
    /// `tile` points in source order, so the feature does not depend on the
    /// tile size. No point inside the range: [`Error::NoPointInRange`].
    ///
    /// With the `std` feature, when `extra` holds
    /// [`crate::arch::Arch::host_block_len`] bytes and the CPU has a block
    /// kernel (x86-64 with AVX2, aarch64 with the dot-product extension),
    /// every block of [`crate::arch::HOST_BLOCK`] points goes through it
    /// instead (`kernel::block`; same values, bit for bit). With
    /// `ready.block`, `extra` holds the weight copies
    /// [`Self::prepare`](super::Int8Model::prepare) made and the block
    /// kernel takes them as they stand.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn encode_into(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        tile: usize,
        feature: &mut [i8],
        work: &mut [i8],
        extra: &mut [i8],
        ready: Ready,
    ) -> Result<u32> {
        if sample.is_empty() {
            return Err(Error::EmptyCloud);
        }
        feature.fill(i8::MIN);
        let tile = tile.clamp(1, MAX_TILE);
        let half = tile * self.p.arch.widest_hidden_encoder();
        let (pairs, spare) = work.split_at_mut((2 * half).min(work.len()));
        let mut pairs = ping_pong(pairs, half)?;
        let expanded = as_words(spare);
        // The block kernel copies the weights first, unless prepared: not
        // worth it when no block can fill.
        #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
        let mut block = if ready.block {
            BlockEncoder::prepared(&self.p.arch, extra)
        } else if sample.len() >= HOST_BLOCK {
            BlockEncoder::new(&self.p.arch, &self.p.encoder, extra)
        } else {
            None
        };
        #[cfg(not(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std")))]
        let _ = ready;
        #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
        let batch = if block.is_some() { HOST_BLOCK } else { tile };
        #[cfg(not(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std")))]
        let (batch, _) = (tile, extra);
        let mut points = [[0i16; INPUT_DIM]; COLLECT];
        let (mut filled, mut encoded, mut left_out) = (0usize, 0usize, 0u32);
        for (index, p) in sample.iter() {
            let Some(q) = self.quantize_point(index, p, map)? else {
                left_out = left_out.saturating_add(1);
                continue;
            };
            if let Some(slot) = points.get_mut(filled) {
                *slot = q;
                filled += 1;
            }
            if filled < batch {
                continue;
            }
            #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
            if let Some(block) = block.as_mut() {
                block.encode(&points, self.block_layers());
                encoded += filled;
                filled = 0;
                continue;
            }
            self.encode_tile(prefix(&points, filled)?, &mut pairs, expanded, feature)?;
            encoded += filled;
            filled = 0;
        }
        #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
        if let Some(block) = block.as_mut() {
            // The last points (fewer than a block) fill one with copies of
            // the first of them: a repeated point leaves the max-pool as it
            // was, and a block costs less than tiles.
            if let Some(&first) = points.first().filter(|_| filled > 0) {
                if let Some(spare) = points.get_mut(filled..) {
                    spare.fill(first);
                }
                block.encode(&points, self.block_layers());
                encoded += filled;
                filled = 0;
            }
            if let Some(last) = self.p.encoder.last() {
                block.pool(requant(last, true), feature);
            }
        }
        // The last points, in tiles (fewer than a block).
        let mut rest = prefix(&points, filled)?;
        while !rest.is_empty() {
            let (now, later) = rest.split_at(tile.min(rest.len()));
            self.encode_tile(now, &mut pairs, expanded, feature)?;
            rest = later;
        }
        encoded += filled;
        if encoded == 0 {
            return Err(Error::NoPointInRange);
        }
        Ok(left_out)
    }

    /// The encoder's layers as the block kernel takes them: input and
    /// output widths, weights and requantization (ReLU on), first to last.
    #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
    fn block_layers(&self) -> impl Iterator<Item = (usize, usize, &[u8], Requant<'_>)> {
        let layers = self.p.arch.encoder_layers().zip(self.p.encoder.iter());
        layers.map(|(s, l)| (s.inputs, s.outputs, l.weights, requant(l, true)))
    }

    /// Runs the encoder's layers on one tile of quantized points (at most
    /// the tile the work buffers were sized for) and max-pools the last
    /// layer into `feature`.
    fn encode_tile<'w>(
        &self,
        points: &[[i16; INPUT_DIM]],
        (a, b): &mut (&'w mut [i8], &'w mut [i8]),
        expanded: &mut [u32],
        feature: &mut [i8],
    ) -> Result<()> {
        let widths = &self.p.arch.encoder;
        let last = widths.len().saturating_sub(1);
        let x0 = points.as_flattened();
        let mut inputs = INPUT_DIM;
        for (l, (layer, &width)) in self.p.encoder.iter().zip(widths.iter()).enumerate() {
            let outputs = width as usize;
            let rq = requant(layer, true);
            let mut sink = if l == last {
                Sink::Pool(&mut *feature)
            } else {
                Sink::Store { out: b, outputs }
            };
            if l == 0 {
                dense_points(layer.weights, rq, x0, &mut sink);
            } else {
                let x = prefix(a, points.len() * inputs)?;
                dense_tile_i8(layer.weights, inputs, rq, x, expanded, &mut sink);
            }
            if l != last {
                core::mem::swap(a, b);
            }
            inputs = outputs;
        }
        Ok(())
    }

    /// Dequantizes an int8 feature to reals (for comparison with the f32 path).
    pub fn dequantize_feature(&self, feature: &[i8], out: &mut [f32]) {
        if let Some(last) = self.p.encoder.last() {
            for (o, &q) in out.iter_mut().zip(feature) {
                *o = (q as i32 - last.out_zero_point as i32) as f32 * last.out_scale;
            }
        }
    }
}
