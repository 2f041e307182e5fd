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
//! weight row is then read once per tile. On an x86-64 host with AVX2 or
//! an aarch64 host with the dot-product extension, given
//! [`Int8Model::host_scratch_len`] bytes of scratch, blocks of
//! [`crate::arch::HOST_BLOCK`] points take the block kernel instead. The
//! result depends on neither (bit for bit).
//!
//! The stages live apart: `check` (what loading proves about a blob),
//! `encode` (points -> quantize -> encoder -> max-pooled feature) and
//! `head` (template and source features -> head -> pose). A PointNetLK
//! step takes the feature to a pose by [`crate::lk`] instead of the head.

mod check;
mod encode;
mod feature;
mod head;
mod prepared;
mod scene;

pub use prepared::Prepared;

use crate::arch::{Arch, MAX_TILE, POSE_DIM};
use crate::error::{Error, Result};
use crate::fixed::INPUT_QMAX;
use crate::format::{self, Int8Layer, Int8Payload, ModelKind, Trailer};
use crate::kernel::{Requant, bytes_of};
use crate::lk::Solver;
use crate::pose::{self, Centring, PointMap, Pose};
use crate::registration::{self, Options, PassCounts, Registration, Sample, Step};
use crate::template::Template;
use crate::track::{self, Tracking};

/// A validated int8 model borrowing its weights from a blob.
#[derive(Debug, Clone)]
pub struct Int8Model<'a> {
    p: Int8Payload<'a>,
    template: Template<'a>,
    lk: Option<Solver<'a>>,
    residual_floor: Option<f32>,
    up: Option<[f32; 3]>,
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
        let (payload, trailer) = format::decode_model::<Int8Payload<'a>>(blob, ModelKind::Int8)?;
        Self::from_payload(payload, trailer)
    }

    /// Parses a blob and checks that `scratch` can run it (one point per tile at least).
    pub fn load(blob: &'a [u8], scratch: &[i8]) -> Result<Self> {
        let model = Self::from_bytes(blob)?;
        model.tile_for(scratch.len())?;
        Ok(model)
    }

    /// Validates an already decoded payload (dimensions, parameter ranges,
    /// accumulator bounds) and its trailer: the template's closest-point
    /// table and PointNetLK's solver, if any.
    #[inline(always)]
    pub fn from_payload(p: Int8Payload<'a>, trailer: Trailer<'a>) -> Result<Self> {
        let lk = crate::lk::solver(trailer.lk, p.arch.feature_dim(), !check::headless(&p))?;
        let residual_floor = registration::checked_floor(trailer.residual_floor)?;
        let up = crate::sweep::checked_up(trailer.up)?;
        // Checked by reference, then moved once into the model.
        let template = Self::validate(&p, trailer.table)?;
        Ok(Int8Model {
            p,
            template,
            lk,
            residual_floor,
            up,
        })
    }

    /// Whether the blob has a head (PCRNet, i-PCRNet); a model trained as
    /// PointNetLK has none and takes its pose from LK steps alone.
    pub fn has_head(&self) -> bool {
        !check::headless(&self.p)
    }

    /// PointNetLK's solver, if the blob has one ([`crate::lk`]).
    pub fn lk_solver(&self) -> Option<&Solver<'a>> {
        self.lk.as_ref()
    }

    /// The recommended options with the steps this blob was trained for
    /// ([`Options::trained`]): i-PCRNet's passes, or a PointNetLK blob's
    /// LK steps with no network pass; and the verdict calibrated by the
    /// template's residual floor when the blob has one.
    pub fn trained_options(&self) -> Options {
        Options::trained(self.trained_passes(), self.has_head(), self.residual_floor)
    }

    /// The template's residual floor (a share of its size) when the
    /// exporter measured one ([`format::Trailer::residual_floor`]).
    pub fn residual_floor(&self) -> Option<f32> {
        self.residual_floor
    }

    /// The template's up axis (unit, template frame) when the exporter was
    /// given one ([`format::Trailer::up`]).
    pub fn up_axis(&self) -> Option<[f32; 3]> {
        self.up
    }

    /// The recommended scene options for this model's object
    /// ([`crate::scene::SceneOptions::for_object`] of
    /// [`Self::object_radius`]) with the blob's up axis, if it has one: then
    /// [`Self::locate`] sweeps the yaw about the plane it finds.
    pub fn scene_options(&self) -> crate::scene::SceneOptions {
        crate::scene::SceneOptions {
            up: self.up,
            ..crate::scene::SceneOptions::for_object(self.object_radius())
        }
    }

    /// The template's points (model frame) used to check and refine poses.
    pub fn template(&self) -> &Template<'a> {
        &self.template
    }

    /// User units -> model frame.
    pub fn frame(&self) -> &format::Frame {
        &self.p.frame
    }

    /// Network passes the model was trained for (1: PCRNet; more: i-PCRNet;
    /// for a model trained as PointNetLK, its LK iterations).
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

    /// Bytes of scratch with which a host (`std` feature; x86-64 with AVX2,
    /// aarch64 with the dot-product extension) encodes
    /// [`crate::arch::HOST_BLOCK`] points at a time
    /// (several times faster; same results, bit for bit): a full tile's
    /// [`Self::scratch_len`] plus [`Arch::host_block_len`], plus room for
    /// the head's folded template half ([`Self::prepare`]: an i32 for each
    /// output of the first hidden head layer). Elsewhere the extra bytes go
    /// unused.
    pub fn host_scratch_len(&self) -> usize {
        self.scratch_len(MAX_TILE) + self.p.arch.host_block_len() + self.folded_len()
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
        self.register_ready(source, options, tile, scratch, Ready::default())
    }

    /// [`Self::register`] with `tile` points per pass on a scratch where
    /// [`Self::prepare`] left what `ready` says.
    #[inline(always)]
    fn register_ready(
        &self,
        source: &[[f32; 3]],
        options: &Options,
        tile: usize,
        scratch: &mut [i8],
        ready: Ready,
    ) -> Result<Registration> {
        registration::run(
            &self.p.frame,
            self.centring(),
            &self.template,
            source,
            options,
            |sample, map, step| self.pass(sample, map, step, tile, scratch, ready),
        )
    }

    /// One tracking step (see [`crate::track`]): refines `previous`, the
    /// pose of the last frame (user units, as a registration or tracking
    /// step returned it; a constant-velocity [`crate::pose::predict`] of the
    /// last two is a better start for a fast object) by ICP on `source`,
    /// and keeps it if reliable; else registers `source` afresh, as
    /// [`Self::register`] does, in the same call. The scratch is the
    /// registration's. A non-finite `previous` or one whose rotation is not
    /// a unit quaternion is [`crate::Error::InvalidPose`].
    #[inline(never)]
    pub fn track(
        &self,
        source: &[[f32; 3]],
        previous: &Pose,
        options: &Options,
        scratch: &mut [i8],
    ) -> Result<Tracking> {
        let tile = self.tile_for(scratch.len())?;
        track::step(
            &self.p.frame,
            self.centring(),
            &self.template,
            source,
            previous,
            options,
            |_| crate::refine::Unguided,
            |sample, map, step| self.pass(sample, map, step, tile, scratch, Ready::default()),
        )
    }

    /// The largest distance of the template's stored points from the
    /// template's centre, user units: the radius the scene stages expect of
    /// the object ([`crate::scene::SceneOptions::for_object`]).
    pub fn object_radius(&self) -> f32 {
        self.template.radius() / self.p.frame.scale
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
    /// point by point while quantizing: no copy of the cloud; at most
    /// [`crate::registration::NETWORK_POINTS`] of its points, every k-th, as
    /// the template's feature was pooled), composing the
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
        self.network_pose_ready(source, passes, tolerance, tile, scratch, Ready::default())
    }

    /// [`Self::network_pose`] with `tile` points per pass on a scratch
    /// where [`Self::prepare`] left what `ready` says.
    #[inline(always)]
    fn network_pose_ready(
        &self,
        source: &[[f32; 3]],
        passes: usize,
        tolerance: f32,
        tile: usize,
        scratch: &mut [i8],
        ready: Ready,
    ) -> Result<(Pose, usize)> {
        registration::network_pose(
            &self.p.frame,
            self.centring(),
            source,
            passes,
            tolerance,
            |sample, map| {
                Ok(self
                    .pass(sample, map, Step::Network, tile, scratch, ready)?
                    .0)
            },
        )
    }

    /// One step on the source moved by `map`, a network pass or a
    /// PointNetLK step: the pose (model frame), the saturation count and
    /// the points left out. `ready` says what [`Self::prepare`] left in the
    /// scratch.
    fn pass(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        step: Step,
        tile: usize,
        scratch: &mut [i8],
        ready: Ready,
    ) -> Result<(Pose, PassCounts)> {
        match step {
            Step::Network => {
                let (_, head, counts) = self.encode_and_head(sample, map, tile, scratch, ready)?;
                Ok((self.pose(&head)?, counts))
            }
            Step::Lk => self.lk_step(sample, map, tile, scratch, ready),
        }
    }

    /// One PointNetLK step ([`crate::lk`]): the encoder on the source moved
    /// by `map`, then `exp(P r)^-1` for the int8 feature residual
    /// `r = q_S - q_T` (in int8 steps, as the stored `P`'s Jacobian).
    fn lk_step(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        tile: usize,
        scratch: &mut [i8],
        ready: Ready,
    ) -> Result<(Pose, PassCounts)> {
        let solver = self.lk.as_ref().ok_or(Error::NoLkSolver)?;
        let (feature, out_of_range) = self.encode_mapped(sample, map, tile, scratch, ready)?;
        let template = self.p.template_feature;
        let residual = |j: usize| match (feature.get(j), template.get(j)) {
            (Some(&s), Some(&t)) => (s as i32 - t as i8 as i32) as f32,
            _ => 0.0,
        };
        let counts = PassCounts {
            saturated: head::count_saturated(feature),
            out_of_range,
        };
        Ok((solver.step(residual)?, counts))
    }

    /// Encodes `source` as a registration's network pass does: centred on
    /// the whole cloud's centroid first if the model says so, then moved
    /// by `motion` (model frame), max-pooled over the sample of
    /// [`registration::network_points`] points (every k-th; the blob's own:
    /// with a head or without), into its int8 global feature
    /// (a view into `scratch`). How the exporter encodes the template's
    /// stored feature (`motion` the identity) and its six small moves for
    /// PointNetLK's Jacobian, as a device LK step encodes a moved source.
    /// ([`Self::encode`] pools every point it is given.)
    pub fn encode_moved<'s>(
        &self,
        source: &[[f32; 3]],
        motion: &Pose,
        scratch: &'s mut [i8],
    ) -> Result<&'s [i8]> {
        let tile = self.tile_for(scratch.len())?;
        let (centring, _) = self.centred(source)?;
        let map = PointMap::new(self.p.frame, &centring.then(motion));
        let sample = Sample::new(source, registration::network_points(self.has_head()));
        Ok(self
            .encode_mapped(sample, &map, tile, scratch, Ready::default())?
            .0)
    }

    /// Encodes `sample` moved by `map` with `tile` points per pass, on a
    /// scratch where [`Self::prepare`] left what `ready` says: the feature
    /// (a view into the scratch) and the points left out (outside the
    /// input range).
    fn encode_mapped<'s>(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        tile: usize,
        scratch: &'s mut [i8],
        ready: Ready,
    ) -> Result<(&'s [i8], u32)> {
        let (feature, work, extra) = self.split_scratch(tile, scratch)?;
        let (block, _) = self.split_host(extra);
        let out_of_range = self.encode_into(sample, map, tile, feature, work, block, ready)?;
        Ok((feature, out_of_range))
    }

    /// Encodes `sample` moved by `map` and runs the head, on a scratch
    /// where [`Self::prepare`] left what `ready` says: the feature (a view
    /// into the scratch), the head's raw outputs and what the pass counted.
    #[inline(always)]
    fn encode_and_head<'s>(
        &self,
        sample: Sample<'_>,
        map: &PointMap,
        tile: usize,
        scratch: &'s mut [i8],
        ready: Ready,
    ) -> Result<(&'s [i8], [i32; POSE_DIM], PassCounts)> {
        let (feature, work, extra) = self.split_scratch(tile, scratch)?;
        let (block, folded) = self.split_host(extra);
        let out_of_range = self.encode_into(sample, map, tile, feature, work, block, ready)?;
        let folded = ready.folded.then(|| bytes_of(folded));
        let (head, saturated) = self.head_counted(feature, work, folded)?;
        let counts = PassCounts {
            saturated,
            out_of_range,
        };
        Ok((feature, head, counts))
    }

    /// Encodes `source` (every point: the low-level calls pool what they
    /// are given, where [`Self::register`] and [`Self::network_pose`] take
    /// a sample) and runs the head, returning the raw results. Uses the
    /// largest tile the scratch allows.
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
        self.infer_ready(source, tile, scratch, Ready::default())
    }

    /// [`Self::infer_tiled`] on a scratch where [`Self::prepare`] left what
    /// `ready` says.
    fn infer_ready<'s>(
        &self,
        source: &[[f32; 3]],
        tile: usize,
        scratch: &'s mut [i8],
        ready: Ready,
    ) -> Result<Int8Inference<'s>> {
        let (centring, map) = self.centred(source)?;
        let (feature, head, counts) =
            self.encode_and_head(Sample::all(source), &map, tile, scratch, ready)?;
        Ok(Int8Inference {
            feature,
            head,
            centring,
            saturated: counts.saturated,
            out_of_range: counts.out_of_range,
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
        let (block, _) = self.split_host(extra);
        let (_, map) = self.centred(source)?;
        self.encode_into(
            Sample::all(source),
            &map,
            tile,
            feature,
            work,
            block,
            Ready::default(),
        )?;
        Ok(feature)
    }

    /// How `source` is moved before the network (centred first if the
    /// model says so; the identity otherwise), and the map into the model
    /// frame that does it.
    fn centred(&self, source: &[[f32; 3]]) -> Result<(Pose, PointMap)> {
        let centring = pose::centring(source, self.centring(), &self.p.frame)?;
        Ok((centring, PointMap::new(self.p.frame, &centring)))
    }

    /// The host area past the device scratch ([`Self::split_scratch`]) as
    /// the block encoder's room ([`Arch::host_block_len`] bytes, or all
    /// there is) and what lies past it (the folded head biases' room).
    fn split_host<'s>(&self, extra: &'s mut [i8]) -> (&'s mut [i8], &'s mut [i8]) {
        let block = self.p.arch.host_block_len().min(extra.len());
        extra.split_at_mut(block)
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
}

/// What [`Int8Model::prepare`] left in a scratch's host area, for the
/// calls on it: the block encoder's weight copies (`block`) and the head's
/// folded template half (`folded`). The default (nothing) is what every
/// call straight on the model takes.
#[derive(Clone, Copy, Debug, Default)]
struct Ready {
    /// (Read where the block kernel exists: a host with the `std` feature.)
    #[cfg_attr(
        not(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std")),
        allow(dead_code)
    )]
    block: bool,
    folded: bool,
}

/// The output step of a layer with its ReLU (`relu`) or without.
fn requant<'l>(layer: &Int8Layer<'l>, relu: bool) -> Requant<'l> {
    Requant {
        bias: layer.bias,
        multiplier: layer.multiplier,
        shift: layer.shift,
        zero_point: layer.out_zero_point,
        act_min: if relu { layer.out_zero_point } else { i8::MIN },
    }
}
