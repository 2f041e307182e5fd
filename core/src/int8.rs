//! The quantized int8 network: points -> quantize -> encode -> head -> pose.
//!
//! Integer-only from the int16 input coordinates to the head's i32 outputs:
//! - input: `q = round(x / input_scale)` as int16, zero point 0 (see
//!   [`crate::fixed::quantize_coordinate`]); int16 rather than int8 because
//!   the input has only 3 channels (the first layer's cost is negligible)
//!   and int8 coordinates measurably cost pose accuracy (see the README);
//! - every layer: int8 weights (symmetric, per output channel), i32 bias,
//!   i32 accumulation, Q31 requantization ([`crate::fixed`]), ReLU fused as
//!   the lower clamp, int8 activations with per-tensor scale and zero point;
//! - max-pool over points on the int8 values of the last encoder layer,
//!   kept as a running max, so working memory does not depend on the number
//!   of points;
//! - head: the first layer reads the template feature (stored in the blob)
//!   and the source feature in place; the output layer's i32 accumulators
//!   are the raw head output.
//!
//! Points go through the encoder in tiles of up to [`MAX_TILE`] points; a
//! weight row is then read once per tile. On an x86-64 host with AVX2 and
//! [`Int8Model::host_scratch_len`] bytes of scratch, blocks of
//! [`crate::arch::HOST_BLOCK`] points take the block kernel instead. The
//! result depends on neither (bit for bit).

use crate::arch::{Arch, INPUT_DIM, MAX_TILE, POSE_DIM, ping_pong, prefix};
use crate::error::{Error, Result};
use crate::fixed::{INPUT_QMAX, MAX_SHIFT, MIN_SHIFT, OutputStep, quantize_coordinate};
use crate::format::{self, Int8Layer, Int8Payload, ModelKind, expect_len, le_f32s, le_i32s};
use crate::kernel::{
    QValue, Requant, Sink, as_words, bytes_of, dense_points, dense_tile, dense_tile_i8,
    dense_vector, dot, rows,
};
use crate::pose::{self, Centring, PointMap, Pose};
use crate::registration::{self, Options, PassCounts, Registration};
use crate::template::Template;
#[cfg(all(target_arch = "x86_64", feature = "std"))]
use crate::{arch::HOST_BLOCK, kernel::block::BlockEncoder};

/// Points collected before they go through the encoder: a host block
/// where the block kernel exists, a tile elsewhere.
#[cfg(all(target_arch = "x86_64", feature = "std"))]
const COLLECT: usize = HOST_BLOCK;
#[cfg(not(all(target_arch = "x86_64", feature = "std")))]
const COLLECT: usize = MAX_TILE;

/// A validated int8 model borrowing its weights from a blob.
#[derive(Debug, Clone)]
pub struct Int8Model<'a> {
    p: Int8Payload<'a>,
    template: Template<'a>,
}

/// Everything one inference produces besides the pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Int8Inference<'s> {
    /// The source's int8 global feature (a view into the scratch).
    pub feature: &'s [i8],
    /// The head's raw i32 outputs `[qw, qx, qy, qz, tx, ty, tz]`: the
    /// network's estimate for the source as it saw it (centred or not).
    pub head: [i32; POSE_DIM],
    /// How the source was moved before the network, in the model frame:
    /// the identity, or the centring translation for models trained on
    /// centred sources. The network's pose in the model frame is
    /// `centring.then(&model.pose(&head)?)`; `frame.pose_to_user` of that
    /// is the pose in user units.
    pub centring: Pose,
    /// Feature entries and head activations at the top of the int8 range.
    pub saturated: u32,
    /// Points left out of the encoder: outside the model's input range.
    pub out_of_range: u32,
}

impl<'a> Int8Model<'a> {
    /// Parses and validates an int8 blob. Weights stay in `blob`.
    ///
    /// Never inlined: the decoder's temporaries (the payload, serde's
    /// sequence buffers) live in this call's frame and are gone when it
    /// returns, instead of joining the caller's frame for the whole
    /// program (the firmware example's `main` grew to 7.4 KB that way).
    #[inline(never)]
    pub fn from_bytes(blob: &'a [u8]) -> Result<Self> {
        let payload: Int8Payload<'a> = format::decode(format::open(blob, ModelKind::Int8)?)?;
        Self::from_payload(payload)
    }

    /// Parses a blob and checks that `scratch` can run it (one point per tile at least).
    pub fn load(blob: &'a [u8], scratch: &[i8]) -> Result<Self> {
        let model = Self::from_bytes(blob)?;
        model.tile_for(scratch.len())?;
        Ok(model)
    }

    /// Validates an already decoded payload (dimensions, parameter ranges,
    /// accumulator bounds).
    #[inline(always)]
    pub fn from_payload(p: Int8Payload<'a>) -> Result<Self> {
        // Checked by reference, then moved once into the model.
        let template = Self::validate(&p)?;
        Ok(Int8Model { p, template })
    }

    /// Every check of [`Self::from_payload`]; returns the template.
    #[inline(never)]
    fn validate(p: &Int8Payload<'a>) -> Result<Template<'a>> {
        let arch = &p.arch;
        arch.validate()?;
        if !(p.input_scale.is_finite() && p.input_scale > 0.0) {
            return Err(Error::InvalidParameter {
                what: "input scale",
            });
        }
        if p.encoder.len() != arch.encoder.len() || p.head.len() != arch.head.len() {
            return Err(Error::InconsistentDimensions {
                what: "layer count differs from architecture",
            });
        }
        for (i, (shape, layer)) in arch.encoder_layers().zip(p.encoder.iter()).enumerate() {
            let xmax = if i == 0 { INPUT_QMAX as i64 } else { 128 };
            check_layer(layer, shape.inputs, shape.outputs, xmax)?;
        }
        for (shape, layer) in arch.head_layers().zip(p.head.iter()) {
            check_layer(layer, shape.inputs, shape.outputs, 128)?;
        }
        let out = &p.output;
        let out_in = arch.head_layers().last().map_or(0, |l| l.inputs);
        expect_len(out.weights, POSE_DIM, out_in, "output weights")?;
        expect_len(out.bias, POSE_DIM, 4, "output bias")?;
        expect_len(out.scale, POSE_DIM, 4, "output scale")?;
        if le_f32s(out.scale).any(|s| !s.is_finite()) {
            return Err(Error::InvalidParameter {
                what: "output scale",
            });
        }
        check_accumulator(out.weights, out.bias, out_in, 128)?;
        expect_len(
            p.template_feature,
            arch.feature_dim(),
            1,
            "template feature",
        )?;
        check_frame(&p.frame)?;
        check_passes(p.passes)?;
        Template::new(p.template.clone())
    }

    /// The template's points (model frame) used to check and refine poses.
    pub fn template(&self) -> &Template<'a> {
        &self.template
    }

    /// User units -> model frame.
    pub fn frame(&self) -> &format::Frame {
        &self.p.frame
    }

    /// Network passes the model was trained for (1: PCRNet; more: i-PCRNet).
    pub fn trained_passes(&self) -> usize {
        self.p.passes as usize
    }

    /// The network shape.
    pub fn arch(&self) -> &Arch {
        &self.p.arch
    }

    /// The decoded payload (quantization parameters and weight views).
    pub fn payload(&self) -> &Int8Payload<'a> {
        &self.p
    }

    /// Bytes of scratch needed with `tile` points per pass.
    pub fn scratch_len(&self, tile: usize) -> usize {
        self.p.arch.int8_scratch_len(tile)
    }

    /// Bytes of scratch with which an x86-64 host with AVX2 (`std`
    /// feature) encodes [`crate::arch::HOST_BLOCK`] points at a time
    /// (several times faster; same results, bit for bit): a full tile's
    /// [`Self::scratch_len`] plus [`Arch::host_block_len`]. Elsewhere the
    /// extra bytes go unused.
    pub fn host_scratch_len(&self) -> usize {
        self.scratch_len(MAX_TILE) + self.p.arch.host_block_len()
    }

    /// The largest tile (up to [`MAX_TILE`]) that fits `available` bytes.
    fn tile_for(&self, available: usize) -> Result<usize> {
        (1..=MAX_TILE)
            .rev()
            .find(|&t| self.scratch_len(t) <= available)
            .ok_or(Error::ScratchTooSmall {
                needed: self.scratch_len(1),
                available,
            })
    }

    /// Registers `source` (user units, any number of points from 1) to the
    /// model's template: the network, then flip resolution and ICP against
    /// the template's points as `options` say, returning the pose in user
    /// units with its residual and flags. See [`crate::registration`].
    // The entry points are never inlined (here and below): each call's
    // stack is its own, as the QEMU harness measures and the README
    // reports it, and a caller's frame does not grow by their temporaries.
    #[inline(never)]
    pub fn register(
        &self,
        source: &[[f32; 3]],
        options: &Options,
        scratch: &mut [i8],
    ) -> Result<Registration> {
        let tile = self.tile_for(scratch.len())?;
        registration::run(
            &self.p.frame,
            self.centring(),
            &self.template,
            source,
            options,
            |map| self.pass(source, map, tile, scratch),
        )
    }

    /// Whether the network sees the source centred on its centroid.
    pub fn centres_source(&self) -> bool {
        self.p.centre_source
    }

    /// How the source is placed for the network: centred on the centroid of
    /// the points within the input range of a robust centre, if the model
    /// centres sources (a stray point the encoder leaves out does not move
    /// the centre either).
    fn centring(&self) -> Centring {
        if self.p.centre_source {
            Centring::Centroid {
                radius: INPUT_QMAX as f32 * self.p.input_scale,
            }
        } else {
            Centring::None
        }
    }

    /// The network alone, in user units: up to `passes` passes (1: PCRNet;
    /// more: i-PCRNet), each on the source moved by the pose so far (moved
    /// point by point while quantizing: no copy of the cloud), composing the
    /// estimates, and stopping early once a pass changes the pose by less
    /// than `tolerance` (`||delta - I||_F`, see [`pose::iterate`]). Returns
    /// the pose and the number of passes. No check, no refinement: use
    /// [`Self::register`] for the main job.
    ///
    /// Choosing `tolerance`: the paper's 1e-7 is never reached. A quantized
    /// pass keeps moving the pose by about 3e-3 to 1e-2, so that rule always
    /// runs every pass. On 200 ModelNet10 test pairs, 1e-2 to 2e-2 stopped
    /// after 8-10 passes on average instead of 20, at the same accuracy
    /// (measured with `pcrnet eval --tolerance`; see the README).
    #[inline(never)]
    pub fn network_pose(
        &self,
        source: &[[f32; 3]],
        passes: usize,
        tolerance: f32,
        scratch: &mut [i8],
    ) -> Result<(Pose, usize)> {
        let tile = self.tile_for(scratch.len())?;
        registration::network_pose(
            &self.p.frame,
            self.centring(),
            source,
            passes,
            tolerance,
            |map| Ok(self.pass(source, map, tile, scratch)?.0),
        )
    }

    /// One network pass on the source moved by `map`: the pose (model
    /// frame), the saturation count and the points left out.
    fn pass(
        &self,
        source: &[[f32; 3]],
        map: &PointMap,
        tile: usize,
        scratch: &mut [i8],
    ) -> Result<(Pose, PassCounts)> {
        let (feature, work, extra) = self.split_scratch(tile, scratch)?;
        let out_of_range = self.encode_into(source, map, tile, feature, work, extra)?;
        let (head, saturated) = self.head_counted(feature, work)?;
        let counts = PassCounts {
            saturated,
            out_of_range,
        };
        Ok((self.pose(&head)?, counts))
    }

    /// Encodes `source` and runs the head, returning the raw results.
    /// Uses the largest tile the scratch allows.
    pub fn infer<'s>(
        &self,
        source: &[[f32; 3]],
        scratch: &'s mut [i8],
    ) -> Result<Int8Inference<'s>> {
        let tile = self.tile_for(scratch.len())?;
        self.infer_tiled(source, tile, scratch)
    }

    /// As [`Self::infer`] with an explicit tile size (`1..=MAX_TILE`).
    #[inline(never)]
    pub fn infer_tiled<'s>(
        &self,
        source: &[[f32; 3]],
        tile: usize,
        scratch: &'s mut [i8],
    ) -> Result<Int8Inference<'s>> {
        let (feature, work, extra) = self.split_scratch(tile, scratch)?;
        let (centring, out_of_range) = self.encode_centred(source, tile, feature, work, extra)?;
        let (head, saturated) = self.head_counted(feature, work)?;
        Ok(Int8Inference {
            feature,
            head,
            centring,
            saturated,
            out_of_range,
        })
    }

    /// Encodes `source` (centred first if the model says so) into its int8
    /// global feature (a view into `scratch`).
    pub fn encode<'s>(&self, source: &[[f32; 3]], scratch: &'s mut [i8]) -> Result<&'s [i8]> {
        let tile = self.tile_for(scratch.len())?;
        self.encode_tiled(source, tile, scratch)
    }

    /// As [`Self::encode`] with an explicit tile size (`1..=MAX_TILE`).
    #[inline(never)]
    pub fn encode_tiled<'s>(
        &self,
        source: &[[f32; 3]],
        tile: usize,
        scratch: &'s mut [i8],
    ) -> Result<&'s [i8]> {
        let (feature, work, extra) = self.split_scratch(tile, scratch)?;
        self.encode_centred(source, tile, feature, work, extra)?;
        Ok(feature)
    }

    /// Encodes `source`, centred first if the model says so; returns how it
    /// was moved (the identity otherwise) and the points left out.
    fn encode_centred(
        &self,
        source: &[[f32; 3]],
        tile: usize,
        feature: &mut [i8],
        work: &mut [i8],
        extra: &mut [i8],
    ) -> Result<(Pose, u32)> {
        let centring = pose::centring(source, self.centring(), &self.p.frame)?;
        let map = PointMap::new(self.p.frame, &centring);
        let out_of_range = self.encode_into(source, &map, tile, feature, work, extra)?;
        Ok((centring, out_of_range))
    }

    /// The scratch as the feature, the encoder's and head's work area (for
    /// `tile` points), and what lies past them (the host kernel's room).
    fn split_scratch<'s>(
        &self,
        tile: usize,
        scratch: &'s mut [i8],
    ) -> Result<(&'s mut [i8], &'s mut [i8], &'s mut [i8])> {
        if !(1..=MAX_TILE).contains(&tile) {
            return Err(Error::InvalidParameter {
                what: "tile outside 1..=MAX_TILE",
            });
        }
        let needed = self.scratch_len(tile);
        let available = scratch.len();
        let too_small = Error::ScratchTooSmall { needed, available };
        let (scratch, extra) = scratch.split_at_mut_checked(needed).ok_or(too_small)?;
        let (feature, work) = scratch
            .split_at_mut_checked(self.p.arch.feature_dim())
            .ok_or(too_small)?;
        Ok((feature, work, extra))
    }

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

    /// Encodes `source`, each point first moved by `map`, into `feature`
    /// (max-pooled over the points). Points outside the input range are
    /// left out; returns how many. Those inside are packed into tiles of
    /// `tile` points in source order, so the feature does not depend on the
    /// tile size. No point inside the range: [`Error::NoPointInRange`].
    ///
    /// On x86-64 with the `std` feature, when `extra` holds
    /// [`Arch::host_block_len`] bytes and the CPU has AVX2, every full
    /// block of [`HOST_BLOCK`] points goes through the block kernel
    /// instead ([`crate::kernel::block`]; same values, bit for bit).
    fn encode_into(
        &self,
        source: &[[f32; 3]],
        map: &PointMap,
        tile: usize,
        feature: &mut [i8],
        work: &mut [i8],
        extra: &mut [i8],
    ) -> Result<u32> {
        if source.is_empty() {
            return Err(Error::EmptyCloud);
        }
        feature.fill(i8::MIN);
        let tile = tile.clamp(1, MAX_TILE);
        let half = tile * self.p.arch.widest_hidden_encoder();
        let (pairs, spare) = work.split_at_mut((2 * half).min(work.len()));
        let mut pairs = ping_pong(pairs, half)?;
        let expanded = as_words(spare);
        // The block kernel copies the weights first: not worth it when no
        // block can fill.
        #[cfg(all(target_arch = "x86_64", feature = "std"))]
        let mut block = (source.len() >= HOST_BLOCK)
            .then(|| BlockEncoder::new(&self.p.arch, &self.p.encoder, extra))
            .flatten();
        #[cfg(all(target_arch = "x86_64", feature = "std"))]
        let batch = if block.is_some() { HOST_BLOCK } else { tile };
        #[cfg(not(all(target_arch = "x86_64", feature = "std")))]
        let (batch, _) = (tile, extra);
        let mut points = [[0i16; INPUT_DIM]; COLLECT];
        let (mut filled, mut encoded, mut left_out) = (0usize, 0usize, 0u32);
        for (index, p) in source.iter().enumerate() {
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
            #[cfg(all(target_arch = "x86_64", feature = "std"))]
            if let Some(block) = block.as_mut() {
                let layers = self.p.arch.encoder_layers().zip(self.p.encoder.iter());
                let layers =
                    layers.map(|(s, l)| (s.inputs, s.outputs, l.weights, requant(l, true)));
                block.encode(&points, layers, feature);
                encoded += filled;
                filled = 0;
                continue;
            }
            self.encode_tile(prefix(&points, filled)?, &mut pairs, expanded, feature)?;
            encoded += filled;
            filled = 0;
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

    /// Runs the head on a source feature: returns the output layer's raw
    /// i32 accumulators. `work` needs `2 x` the widest hidden head layer.
    pub fn head(&self, source_feature: &[i8], work: &mut [i8]) -> Result<[i32; POSE_DIM]> {
        Ok(self.head_counted(source_feature, work)?.0)
    }

    /// [`Self::head`], also counting the feature entries and hidden head
    /// activations at `i8::MAX` (saturated).
    fn head_counted(
        &self,
        source_feature: &[i8],
        work: &mut [i8],
    ) -> Result<([i32; POSE_DIM], u32)> {
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
                let parts = [template, bytes_of(source_feature)];
                if !dense_vector(layer.weights, &parts, rq, expanded, out) {
                    let mut sink = Sink::Store {
                        out,
                        outputs: width,
                    };
                    head_first_layer(layer.weights, f, rq, template, source_feature, &mut sink);
                }
            } else {
                let x = prefix(a, len)?;
                if !dense_vector(layer.weights, &[bytes_of(x)], rq, expanded, out) {
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

    /// Dequantizes an int8 feature to reals (for comparison with the f32 path).
    pub fn dequantize_feature(&self, feature: &[i8], out: &mut [f32]) {
        if let Some(last) = self.p.encoder.last() {
            for (o, &q) in out.iter_mut().zip(feature) {
                *o = (q as i32 - last.out_zero_point as i32) as f32 * last.out_scale;
            }
        }
    }
}

/// Values at `i8::MAX`, the top of the activation range.
fn count_saturated(values: &[i8]) -> u32 {
    values.iter().filter(|&&v| v == i8::MAX).count() as u32
}

/// Checks a blob's trained pass count (at least 1).
pub(crate) fn check_passes(passes: u16) -> Result<()> {
    if passes >= 1 {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            what: "trained passes must be at least 1",
        })
    }
}

/// Checks a blob's frame: finite centre, finite positive scale.
pub(crate) fn check_frame(frame: &format::Frame) -> Result<()> {
    if frame.centre.iter().all(|c| c.is_finite()) && frame.scale.is_finite() && frame.scale > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            what: "frame centre or scale",
        })
    }
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

fn requant<'l>(layer: &Int8Layer<'l>, relu: bool) -> Requant<'l> {
    Requant {
        bias: layer.bias,
        multiplier: layer.multiplier,
        shift: layer.shift,
        zero_point: layer.out_zero_point,
        act_min: if relu { layer.out_zero_point } else { i8::MIN },
    }
}

fn check_layer(layer: &Int8Layer<'_>, inputs: usize, outputs: usize, xmax: i64) -> Result<()> {
    expect_len(layer.weights, outputs, inputs, "layer weights")?;
    expect_len(layer.bias, outputs, 4, "layer bias")?;
    expect_len(layer.multiplier, outputs, 4, "layer multiplier")?;
    expect_len(layer.shift, outputs, 1, "layer shift")?;
    if !(layer.out_scale.is_finite() && layer.out_scale > 0.0) {
        return Err(Error::InvalidParameter {
            what: "output scale",
        });
    }
    if le_i32s(layer.multiplier).any(|m| m < 0) {
        return Err(Error::InvalidParameter {
            what: "negative multiplier",
        });
    }
    if layer
        .shift
        .iter()
        .any(|&s| !(MIN_SHIFT..=MAX_SHIFT).contains(&(s as i8)))
    {
        return Err(Error::InvalidParameter {
            what: "shift outside -31..=31",
        });
    }
    check_accumulator(layer.weights, layer.bias, inputs, xmax)
}

/// Proves that no accumulator can leave the i32 range:
/// `|bias| + sum_i |w_i| * xmax <= i32::MAX` for every output row.
fn check_accumulator(weights: &[u8], bias: &[u8], inputs: usize, xmax: i64) -> Result<()> {
    for (row, b) in rows(weights, inputs).zip(le_i32s(bias)) {
        let sum: i64 = row.iter().map(|&w| (w as i8 as i64).abs()).sum();
        if (b as i64).abs() + sum * xmax > i32::MAX as i64 {
            return Err(Error::InvalidParameter {
                what: "bias and weights can overflow the i32 accumulator",
            });
        }
    }
    Ok(())
}
