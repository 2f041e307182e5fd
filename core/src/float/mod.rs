//! The f32 reference network: the same shape as the int8 path ([`Arch`]),
//! in plain f32 arithmetic.
//!
//! It serves the host (training, validation, measuring quantization error)
//! and is available on the device too. The weights are generic over
//! [`Params`], so the same forward runs on a blob (little-endian bytes,
//! [`LeF32`]) and on the trainer's `&[f32]` arrays. Sums run over inputs in
//! ascending order, one IEEE-754 operation at a time, so results are
//! deterministic (but not bit-identical to the int8 path, of course).

use crate::arch::{Arch, F32_TILE, INPUT_DIM, POSE_DIM, ping_pong, prefix};
use crate::error::{Error, Result};
use crate::format::{self, F32Layer, F32Payload, Frame, ModelKind, Trailer, expect_len};
use crate::lk::Solver;
use crate::pose::{self, Centring, PointMap, Pose};
use crate::registration::{self, Options, PassCounts, Registration, Sample, Step};
use crate::template::Template;
use crate::track::{self, Tracking};

#[cfg(all(target_arch = "x86_64", feature = "std"))]
mod x86;

/// Read access to an array of f32 parameters.
pub trait Params: Copy {
    /// Number of values.
    fn len(self) -> usize;
    /// Whether there are no values.
    fn is_empty(self) -> bool {
        self.len() == 0
    }
    /// The value at `i` (0.0 past the end; sizes are validated beforehand).
    fn get(self, i: usize) -> f32;
    /// The `len` values from `start` (fewer past the end).
    fn slice(self, start: usize, len: usize) -> Self;
    /// The values in order.
    fn values(self) -> impl Iterator<Item = f32>;
    /// The first eight values (zeros past the end).
    #[inline(always)]
    fn first8(self) -> [f32; 8] {
        let mut out = [0f32; 8];
        for (o, v) in out.iter_mut().zip(self.values()) {
            *o = v;
        }
        out
    }
}

impl Params for &[f32] {
    fn len(self) -> usize {
        <[f32]>::len(self)
    }
    #[inline(always)]
    fn get(self, i: usize) -> f32 {
        <[f32]>::get(self, i).copied().unwrap_or(0.0)
    }
    #[inline(always)]
    fn slice(self, start: usize, len: usize) -> Self {
        let rest = <[f32]>::get(self, start..).unwrap_or(&[]);
        rest.get(..len).unwrap_or(rest)
    }
    #[inline(always)]
    fn values(self) -> impl Iterator<Item = f32> {
        self.iter().copied()
    }
}

/// f32 values stored little-endian in bytes (as in a blob; no alignment needed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LeF32<'a>(pub &'a [u8]);

impl Params for LeF32<'_> {
    #[inline(always)]
    fn len(self) -> usize {
        self.0.len() / 4
    }
    #[inline(always)]
    fn first8(self) -> [f32; 8] {
        let mut out = [0f32; 8];
        match self.0.first_chunk::<32>() {
            // A whole chunk: one 32-byte copy, no per-value end checks.
            Some(bytes) => {
                for (o, w) in out.iter_mut().zip(bytes.as_chunks::<4>().0) {
                    *o = f32::from_le_bytes(*w);
                }
            }
            None => {
                for (o, v) in out.iter_mut().zip(self.values()) {
                    *o = v;
                }
            }
        }
        out
    }
    #[inline(always)]
    fn get(self, i: usize) -> f32 {
        match self.0.get(4 * i..4 * i + 4) {
            Some(&[a, b, c, d]) => f32::from_le_bytes([a, b, c, d]),
            _ => 0.0,
        }
    }
    #[inline(always)]
    fn slice(self, start: usize, len: usize) -> Self {
        let rest = self.0.get(4 * start..).unwrap_or(&[]);
        LeF32(rest.get(..4 * len).unwrap_or(rest))
    }
    #[inline(always)]
    fn values(self) -> impl Iterator<Item = f32> {
        self.0
            .as_chunks::<4>()
            .0
            .iter()
            .map(|&b| f32::from_le_bytes(b))
    }
}

/// One dense layer: `outputs x inputs` weights (row-major by output) and biases.
#[derive(Debug, Clone, Copy)]
pub struct Layer<P> {
    /// Weights.
    pub weights: P,
    /// Biases.
    pub bias: P,
}

/// An f32 network: weights and the template feature, over any [`Params`].
#[derive(Debug, Clone)]
pub struct F32Network<P> {
    arch: Arch,
    centre_source: bool,
    layers: heapless::Vec<Layer<P>, { 2 * crate::arch::MAX_LAYERS + 1 }>,
    template: P,
}

/// The f32 model read from a blob: the network, its frame and the
/// template's points, so it runs the same pipeline as [`crate::Int8Model`].
#[derive(Debug, Clone)]
pub struct F32Model<'a> {
    network: F32Network<LeF32<'a>>,
    passes: u16,
    frame: Frame,
    template: Template<'a>,
    lk: Option<Solver<'a>>,
    residual_floor: Option<f32>,
    up: Option<[f32; 3]>,
}

impl<'a> F32Model<'a> {
    /// Parses and validates an f32 blob. Weights stay in `blob`.
    pub fn from_bytes(blob: &'a [u8]) -> Result<Self> {
        let (payload, trailer) = format::decode_model(blob, ModelKind::F32)?;
        Self::from_payload(payload, trailer)
    }

    /// The network (model frame).
    pub fn network(&self) -> &F32Network<LeF32<'a>> {
        &self.network
    }

    /// User units -> model frame.
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// Network passes the model was trained for (1: PCRNet; more: i-PCRNet;
    /// for a model trained as PointNetLK, its LK iterations).
    pub fn trained_passes(&self) -> usize {
        self.passes as usize
    }

    /// PointNetLK's solver, if the blob has one ([`crate::lk`]).
    pub fn lk_solver(&self) -> Option<&Solver<'a>> {
        self.lk.as_ref()
    }

    /// The recommended options with the steps this blob was trained for,
    /// as [`crate::Int8Model::trained_options`].
    pub fn trained_options(&self) -> Options {
        Options::trained(
            self.trained_passes(),
            self.network.has_head(),
            self.residual_floor,
        )
    }

    /// The template's residual floor when the exporter measured one, as
    /// [`crate::Int8Model::residual_floor`].
    pub fn residual_floor(&self) -> Option<f32> {
        self.residual_floor
    }

    /// [`crate::Int8Model::up_axis`].
    pub fn up_axis(&self) -> Option<[f32; 3]> {
        self.up
    }

    /// Registers a cut single view seen from `viewpoint`, as
    /// [`crate::Int8Model::register_view`], with the f32 network.
    ///
    /// # Errors
    /// As [`Self::register`] and [`crate::scene::View::render`].
    pub fn register_view(
        &self,
        source: &[[f32; 3]],
        viewpoint: [f32; 3],
        options: &Options,
        scratch: &mut [f32],
        buffer: &mut [f32],
    ) -> Result<crate::viewed::Viewed> {
        let net = &self.network;
        crate::viewed::register(
            &self.frame,
            net.centring(),
            &self.template,
            source,
            viewpoint,
            options,
            buffer,
            |sample, map, step| self.step(sample, map, step, scratch),
        )
    }

    /// One tracking step of a cut single view seen from `viewpoint`, as
    /// [`crate::Int8Model::track_view`], with the f32 network.
    ///
    /// # Errors
    /// As [`crate::Int8Model::track_view`].
    pub fn track_view(
        &self,
        source: &[[f32; 3]],
        previous: &Pose,
        viewpoint: [f32; 3],
        options: &Options,
        scratch: &mut [f32],
        buffer: &mut [f32],
    ) -> Result<Tracking> {
        let net = &self.network;
        crate::viewed::track(
            &self.frame,
            net.centring(),
            &self.template,
            source,
            previous,
            viewpoint,
            options,
            buffer,
            |sample, map, step| self.step(sample, map, step, scratch),
        )
    }

    /// Checks `pose` against the cut single view `source` seen from
    /// `viewpoint`, as [`crate::Int8Model::check_view`].
    ///
    /// # Errors
    /// As [`crate::Int8Model::check_view`].
    pub fn check_view(
        &self,
        source: &[[f32; 3]],
        viewpoint: [f32; 3],
        pose: &Pose,
        buffer: &mut [f32],
    ) -> Result<crate::scene::Verification> {
        crate::scene::view::check_model(
            &self.template,
            &self.frame,
            source,
            viewpoint,
            pose,
            buffer,
        )
    }

    /// One step on the source moved by `map`: a network pass or a
    /// PointNetLK step (`exp(P r)^-1` for the f32 feature residual).
    fn step(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        step: Step,
        scratch: &mut [f32],
    ) -> Result<(Pose, PassCounts)> {
        let net = &self.network;
        let pose = match step {
            Step::Network => net.pass(sample, map, scratch)?,
            Step::Lk => {
                let solver = self.lk.as_ref().ok_or(Error::NoLkSolver)?;
                let feature = net.encode_mapped(sample, map, scratch)?;
                let template = net.template;
                solver.step(|j| match feature.get(j) {
                    Some(&s) => s - template.get(j),
                    None => 0.0,
                })?
            }
        };
        Ok((pose, PassCounts::default()))
    }

    /// The template's points (model frame).
    pub fn template(&self) -> &Template<'a> {
        &self.template
    }

    /// Elements of f32 scratch needed.
    pub fn scratch_len(&self) -> usize {
        self.network.scratch_len()
    }

    /// Elements of f32 scratch with which a host runs the encoder
    /// [`F32_TILE`] points at a time (see [`F32Network::tiled_scratch_len`]).
    pub fn tiled_scratch_len(&self) -> usize {
        self.network.tiled_scratch_len()
    }

    /// Whether the network sees the source centred on its centroid.
    pub fn centres_source(&self) -> bool {
        self.network.centre_source
    }

    /// The main job, as [`crate::Int8Model::register`], with the f32 network.
    pub fn register(
        &self,
        source: &[[f32; 3]],
        options: &Options,
        scratch: &mut [f32],
    ) -> Result<Registration> {
        let net = &self.network;
        registration::run(
            &self.frame,
            net.centring(),
            &self.template,
            source,
            options,
            |sample, map, step| self.step(sample, map, step, scratch),
        )
    }

    /// One tracking step, as [`crate::Int8Model::track`], with the f32
    /// network for the fallback.
    pub fn track(
        &self,
        source: &[[f32; 3]],
        previous: &Pose,
        options: &Options,
        scratch: &mut [f32],
    ) -> Result<Tracking> {
        let net = &self.network;
        track::step(
            &self.frame,
            net.centring(),
            &self.template,
            source,
            previous,
            options,
            |_| crate::refine::Unguided,
            |sample, map, step| self.step(sample, map, step, scratch),
        )
    }

    /// The network alone, in user units, as [`crate::Int8Model::network_pose`].
    pub fn network_pose(
        &self,
        source: &[[f32; 3]],
        passes: usize,
        tolerance: f32,
        scratch: &mut [f32],
    ) -> Result<(Pose, usize)> {
        self.network
            .network_pose_in(&self.frame, source, passes, tolerance, scratch)
    }

    /// Validates an already decoded payload and its trailer (the
    /// template's closest-point table and PointNetLK's solver, if any).
    pub fn from_payload(p: F32Payload<'a>, trailer: Trailer<'a>) -> Result<Self> {
        let mut layers = heapless::Vec::new();
        for l in &p.layers {
            check_bytes(l)?;
            // Same capacity as `p.layers`: cannot overflow.
            let _ = layers.push(Layer {
                weights: LeF32(l.weights),
                bias: LeF32(l.bias),
            });
        }
        expect_len(
            p.template_feature,
            p.arch.feature_dim(),
            4,
            "template feature",
        )?;
        crate::format::check_frame(&p.frame)?;
        crate::format::check_passes(p.passes)?;
        let network = F32Network::new(p.arch, layers, LeF32(p.template_feature))?
            .with_centring(p.centre_source);
        let lk = crate::lk::solver(trailer.lk, network.arch.feature_dim(), network.has_head())?;
        let residual_floor = crate::registration::checked_floor(trailer.residual_floor)?;
        let up = crate::sweep::checked_up(trailer.up)?;
        Ok(F32Model {
            network,
            passes: p.passes,
            frame: p.frame,
            template: Template::new(p.template, trailer.table)?,
            lk,
            residual_floor,
            up,
        })
    }
}

fn check_bytes(l: &F32Layer<'_>) -> Result<()> {
    if !l.weights.len().is_multiple_of(4) || !l.bias.len().is_multiple_of(4) {
        return Err(Error::InconsistentDimensions {
            what: "f32 array length not a multiple of 4",
        });
    }
    Ok(())
}

const LAYER_COUNT: Error = Error::InconsistentDimensions {
    what: "layer count differs from architecture",
};

impl<P: Params> F32Network<P> {
    /// Builds a network from its layers (encoder first, then head, output
    /// last) and the template feature, checking every size against `arch`.
    /// A network without hidden head layers may also come without its
    /// output layer: an encoder alone (a model trained as PointNetLK;
    /// [`Self::head`] is then [`Error::NoHead`]).
    pub fn new(
        arch: Arch,
        layers: heapless::Vec<Layer<P>, { 2 * crate::arch::MAX_LAYERS + 1 }>,
        template: P,
    ) -> Result<Self> {
        arch.validate()?;
        let shapes = arch.encoder_layers().chain(arch.head_layers());
        let encoder = arch.encoder_layers().count();
        let headless = arch.head.is_empty() && layers.len() == encoder;
        if encoder + arch.head_layers().count() != layers.len() && !headless {
            return Err(LAYER_COUNT);
        }
        for (s, l) in shapes.zip(layers.iter()) {
            // Checked: on a 32-bit core a head of 131,070 x 32,769 wraps
            // to a small count and would pass an unchecked comparison.
            if s.inputs.checked_mul(s.outputs) != Some(l.weights.len()) || l.bias.len() != s.outputs
            {
                return Err(Error::InconsistentDimensions {
                    what: "layer weights",
                });
            }
        }
        if template.len() != arch.feature_dim() {
            return Err(Error::InconsistentDimensions {
                what: "template feature",
            });
        }
        Ok(F32Network {
            arch,
            centre_source: false,
            layers,
            template,
        })
    }

    /// The network shape.
    pub fn arch(&self) -> &Arch {
        &self.arch
    }

    /// Whether the network has a head (an encoder alone otherwise).
    pub fn has_head(&self) -> bool {
        self.layers.len() > self.arch.encoder.len()
    }

    /// Sets whether the network expects the source centred on its centroid
    /// (see [`pose::centring`]; off by default).
    pub fn with_centring(mut self, centre_source: bool) -> Self {
        self.centre_source = centre_source;
        self
    }

    /// Whether the network sees the source centred on its centroid.
    pub fn centres_source(&self) -> bool {
        self.centre_source
    }

    /// How the source is placed for the network: the f32 path has no input
    /// range, so a centred source is centred on the centroid of every point.
    pub fn centring(&self) -> Centring {
        if self.centre_source {
            Centring::Centroid {
                radius: f32::INFINITY,
            }
        } else {
            Centring::None
        }
    }

    /// The layers: encoder first, then head, output last.
    pub fn layers(&self) -> &[Layer<P>] {
        &self.layers
    }

    /// The template feature.
    pub fn template(&self) -> P {
        self.template
    }

    /// Elements of f32 scratch needed.
    pub fn scratch_len(&self) -> usize {
        self.arch.f32_scratch_len()
    }

    /// Elements of f32 scratch with which the encoder runs [`F32_TILE`]
    /// points at a time where a host kernel does so (x86-64 with AVX and
    /// the `std` feature); elsewhere the extra is unused. Results are the
    /// same bits either way: each point's sums keep their order.
    pub fn tiled_scratch_len(&self) -> usize {
        let feature = self.arch.feature_dim();
        let tiles = 2 * F32_TILE * self.arch.widest_hidden_encoder();
        self.scratch_len().max(feature + tiles)
    }

    /// Encodes the source (centred first if the network says so; every
    /// point, where a registration's pass takes a sample) and runs the
    /// head, returning the raw 7 outputs. The feature is left in
    /// `scratch[..F]`.
    pub fn infer(&self, source: &[[f32; 3]], scratch: &mut [f32]) -> Result<[f32; POSE_DIM]> {
        let (feature, work) = self.split(scratch)?;
        self.encode_centred(source, feature, work)?;
        self.head(feature, work)
    }

    /// Encodes `source`, centred first if the network says so; returns how
    /// it was moved (the identity otherwise).
    fn encode_centred(
        &self,
        source: &[[f32; 3]],
        feature: &mut [f32],
        work: &mut [f32],
    ) -> Result<Pose> {
        let centring = pose::centring(source, self.centring(), &Frame::IDENTITY)?;
        let map = PointMap::new(Frame::IDENTITY, &centring);
        self.encode_into(Sample::all(source), &map, feature, work)?;
        Ok(centring)
    }

    /// The network alone on clouds in its own frame, as
    /// [`crate::Int8Model::network_pose`]: up to `passes` passes composed,
    /// stopping once a pass's `||dT - I||_F` is below `tolerance`.
    pub fn network_pose(
        &self,
        source: &[[f32; 3]],
        passes: usize,
        tolerance: f32,
        scratch: &mut [f32],
    ) -> Result<(Pose, usize)> {
        self.network_pose_in(&Frame::IDENTITY, source, passes, tolerance, scratch)
    }

    fn network_pose_in(
        &self,
        frame: &Frame,
        source: &[[f32; 3]],
        passes: usize,
        tolerance: f32,
        scratch: &mut [f32],
    ) -> Result<(Pose, usize)> {
        registration::network_pose(
            frame,
            self.centring(),
            source,
            passes,
            tolerance,
            |sample, map| self.pass(sample, map, scratch),
        )
    }

    /// One pass on `sample` moved by `map`: the pose in the model frame.
    fn pass(&self, sample: Sample<'_>, map: &PointMap, scratch: &mut [f32]) -> Result<Pose> {
        let (feature, work) = self.split(scratch)?;
        self.encode_into(sample, map, feature, work)?;
        Pose::from_head_output(&self.head(feature, work)?)
    }

    /// Encodes `source` into its global feature (a view into `scratch`;
    /// [`Error::NonFiniteResult`] if an entry overflows f32).
    pub fn encode<'s>(&self, source: &[[f32; 3]], scratch: &'s mut [f32]) -> Result<&'s [f32]> {
        let (feature, work) = self.split(scratch)?;
        self.encode_centred(source, feature, work)?;
        finite(feature)?;
        Ok(feature)
    }

    /// Encodes `source` as a registration's network pass does: centred on
    /// the whole cloud first if the network says so, then moved by
    /// `motion`, max-pooled over the sample of
    /// [`registration::network_points`] points (the blob's own: with a
    /// head or without): the exporter's encodings of the template's stored feature
    /// (`motion` the identity) and of its six small moves for PointNetLK's
    /// Jacobian. ([`Self::encode`] pools every point it is given.)
    pub fn encode_moved<'s>(
        &self,
        source: &[[f32; 3]],
        motion: &Pose,
        scratch: &'s mut [f32],
    ) -> Result<&'s [f32]> {
        let centring = pose::centring(source, self.centring(), &Frame::IDENTITY)?;
        let map = PointMap::new(Frame::IDENTITY, &centring.then(motion));
        let points = registration::network_points(self.has_head());
        self.encode_mapped(Sample::new(source, points), &map, scratch)
    }

    /// Encodes `sample`, each point first moved by `map`, into its global
    /// feature (a view into `scratch`; [`Error::NonFiniteResult`] if an
    /// entry overflows f32).
    fn encode_mapped<'s>(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        scratch: &'s mut [f32],
    ) -> Result<&'s [f32]> {
        let (feature, work) = self.split(scratch)?;
        self.encode_into(sample, map, feature, work)?;
        finite(feature)?;
        Ok(feature)
    }

    fn split<'s>(&self, scratch: &'s mut [f32]) -> Result<(&'s mut [f32], &'s mut [f32])> {
        let needed = self.scratch_len();
        let available = scratch.len();
        if available < needed {
            return Err(Error::ScratchTooSmall { needed, available });
        }
        // All of it: a host kernel may use more than the minimum.
        scratch
            .split_at_mut_checked(self.arch.feature_dim())
            .ok_or(Error::ScratchTooSmall { needed, available })
    }

    /// Encodes `sample`, each point first moved by `map`.
    fn encode_into(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        feature: &mut [f32],
        work: &mut [f32],
    ) -> Result<()> {
        if sample.is_empty() {
            return Err(Error::EmptyCloud);
        }
        feature.fill(f32::NEG_INFINITY);
        let encoder = self.encoder_layers()?;
        #[cfg(all(target_arch = "x86_64", feature = "std"))]
        if x86::encode(encoder, &self.arch, sample, map, feature, work)? {
            return Ok(());
        }
        let (mut a, mut b) = ping_pong(work, self.arch.widest_hidden_encoder())?;
        for (index, p) in sample.iter() {
            if p.iter().any(|x| !x.is_finite()) {
                return Err(Error::NonFiniteCoordinate { index });
            }
            let p = map.apply(*p);
            let mut inputs = INPUT_DIM;
            for (l, (layer, shape)) in encoder.iter().zip(self.arch.encoder_layers()).enumerate() {
                let x: &[f32] = if l == 0 { &p } else { prefix(a, inputs)? };
                if l + 1 == encoder.len() {
                    dense(layer, x, shape.outputs, true, |o, v| {
                        if let Some(f) = feature.get_mut(o) {
                            pool(f, v);
                        }
                    });
                } else {
                    dense(layer, x, shape.outputs, true, |o, v| {
                        if let Some(y) = b.get_mut(o) {
                            *y = v;
                        }
                    });
                    core::mem::swap(&mut a, &mut b);
                }
                inputs = shape.outputs;
            }
        }
        Ok(())
    }

    /// The encoder's layers (validated at construction: the error is
    /// unreachable, and no panic path is left to the compiler).
    fn encoder_layers(&self) -> Result<&[Layer<P>]> {
        self.layers
            .get(..self.arch.encoder.len())
            .ok_or(LAYER_COUNT)
    }

    /// Runs the head on a source feature, returning the raw 7 outputs
    /// ([`Error::NonFiniteResult`] if one overflows f32).
    pub fn head(&self, source_feature: &[f32], work: &mut [f32]) -> Result<[f32; POSE_DIM]> {
        if !self.has_head() {
            return Err(Error::NoHead);
        }
        let f = self.arch.feature_dim();
        if source_feature.len() != f {
            return Err(Error::InconsistentDimensions {
                what: "source feature length",
            });
        }
        let (mut a, mut b) = ping_pong(work, self.arch.widest_hidden_head())?;
        // The first layer reads (template, source) in place.
        let head = self
            .layers
            .get(self.arch.encoder.len()..)
            .ok_or(LAYER_COUNT)?;
        let mut raw = [0f32; POSE_DIM];
        let mut len = 0usize;
        for (layer, shape) in head.iter().zip(self.arch.head_layers()) {
            let relu = shape.relu;
            let mut emit = |o: usize, v: f32| {
                let slot = if relu { b.get_mut(o) } else { raw.get_mut(o) };
                if let Some(y) = slot {
                    *y = v;
                }
            };
            if len == 0 {
                dense_concat(
                    layer,
                    self.template,
                    source_feature,
                    shape.outputs,
                    relu,
                    &mut emit,
                );
            } else {
                dense(layer, prefix(a, len)?, shape.outputs, relu, &mut emit);
            }
            if relu {
                len = shape.outputs;
                core::mem::swap(&mut a, &mut b);
            }
        }
        finite(&raw)?;
        Ok(raw)
    }
}

/// One point's step of the max-pool: `v` replaces `f` only if larger, so
/// the first of equal values (and of `-0.0` and `0.0`) stays and a NaN
/// never enters. Every encoder path pools point by point in source order
/// through this, which is what keeps their bits equal.
#[inline(always)]
fn pool(f: &mut f32, v: f32) {
    if v > *f {
        *f = v;
    }
}

/// Coordinates far beyond the model's range overflow f32 in the layers: a
/// feature or head output that is not finite is an error, never a value.
fn finite(values: &[f32]) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::NonFiniteResult)
    }
}

/// `y[o] = b[o] + sum_i w[o][i] x[i]` (then ReLU), passed to `emit(o, y)`.
#[inline]
pub fn dense<P: Params>(
    layer: &Layer<P>,
    x: &[f32],
    outputs: usize,
    relu: bool,
    emit: impl FnMut(usize, f32),
) {
    dense_concat(layer, &[][..], x, outputs, relu, emit)
}

/// As [`dense`] with the input being the concatenation `a ++ x`.
#[inline]
fn dense_concat<P: Params, A: Params>(
    layer: &Layer<P>,
    a: A,
    x: &[f32],
    outputs: usize,
    relu: bool,
    mut emit: impl FnMut(usize, f32),
) {
    #[cfg(all(target_arch = "x86_64", feature = "std"))]
    let first = x86::dense_concat(layer, a, x, outputs, relu, &mut emit);
    #[cfg(not(all(target_arch = "x86_64", feature = "std")))]
    let first = 0;
    let inputs = a.len() + x.len();
    for o in first..outputs {
        let base = o * inputs;
        let mut acc = layer.bias.get(o);
        for i in 0..a.len() {
            acc += layer.weights.get(base + i) * a.get(i);
        }
        let base = base + a.len();
        for (i, &xi) in x.iter().enumerate() {
            acc += layer.weights.get(base + i) * xi;
        }
        emit(o, if relu && acc < 0.0 { 0.0 } else { acc });
    }
}
