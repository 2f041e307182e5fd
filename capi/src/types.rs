//! The C types the functions exchange: the status every call returns, the
//! registration options, and the result, each with its conversion from or
//! to `pcrnet-core`'s Rust type.

use PcrnetStatus::*;
use pcrnet_core::{Degeneracy, Error, Metric, Options, Registration};

/// Status of a call: `PCRNET_OK` (0) or what went wrong (negative).
#[repr(i32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(non_camel_case_types, clippy::upper_case_acronyms)]
pub enum PcrnetStatus {
    /// Success; outputs were written.
    PCRNET_OK = 0,
    /// A required pointer is null.
    PCRNET_ERROR_NULL_POINTER = -1,
    /// An array is not aligned for its type (points: 4 bytes; depth
    /// values and labels: 2).
    PCRNET_ERROR_MISALIGNED = -2,
    /// The model handle was not filled by a successful `pcrnet_model_load`.
    PCRNET_ERROR_NOT_LOADED = -3,
    /// The prepared handle was not filled by a successful `pcrnet_prepare`.
    PCRNET_ERROR_NOT_PREPARED = -4,
    /// The blob does not start with the magic bytes `PCRN`.
    PCRNET_ERROR_BAD_MAGIC = -10,
    /// The blob's format version is not one this build reads.
    PCRNET_ERROR_UNSUPPORTED_VERSION = -11,
    /// The blob holds another kind of model (the C API loads int8 blobs).
    PCRNET_ERROR_WRONG_KIND = -12,
    /// The blob is shorter than its header says.
    PCRNET_ERROR_TRUNCATED = -13,
    /// Bytes follow the blob's CRC.
    PCRNET_ERROR_TRAILING_DATA = -14,
    /// The blob's CRC does not match its contents.
    PCRNET_ERROR_BAD_CRC = -15,
    /// The payload does not decode.
    PCRNET_ERROR_MALFORMED = -16,
    /// Layer sizes disagree.
    PCRNET_ERROR_INCONSISTENT_DIMENSIONS = -17,
    /// A model parameter is outside its range.
    PCRNET_ERROR_INVALID_PARAMETER = -18,
    /// The scratch buffer is smaller than `pcrnet_model_scratch_len(model, 1)`.
    PCRNET_ERROR_SCRATCH_TOO_SMALL = -20,
    /// An output buffer is too small.
    PCRNET_ERROR_BUFFER_TOO_SMALL = -21,
    /// The cloud has no points.
    PCRNET_ERROR_EMPTY_CLOUD = -30,
    /// A coordinate is NaN or infinite.
    PCRNET_ERROR_NON_FINITE_COORDINATE = -31,
    /// Every point is outside the model's input range (points outside it
    /// are left out and counted in `out_of_range`; with none left there is
    /// no pose).
    PCRNET_ERROR_NO_POINT_IN_RANGE = -32,
    /// The network produced a zero quaternion.
    PCRNET_ERROR_DEGENERATE_POSE = -33,
    /// The pose or a residual came out non-finite.
    PCRNET_ERROR_NON_FINITE_RESULT = -34,
    /// A registration option is out of range.
    PCRNET_ERROR_INVALID_OPTION = -40,
    /// The previous pose of `pcrnet_track` is not finite or its quaternion
    /// is not of unit length.
    PCRNET_ERROR_INVALID_POSE = -41,
    /// A depth frame or a scene setting cannot be used: a zero size or
    /// stride, a buffer too short for the frame, intrinsics or a depth
    /// scale not finite and positive, a grid step of 0 or one of more cells
    /// than its labels can number.
    PCRNET_ERROR_INVALID_FRAME = -42,
    /// A network pass was asked of a blob without a head (a model trained
    /// as PointNetLK): set `passes` to 0 and `lk_iterations` to its
    /// trained count.
    PCRNET_ERROR_NO_HEAD = -43,
    /// `lk_iterations` was set for a blob without PointNetLK's solver:
    /// export the model with `pcrnet export --lk`, or set it to 0.
    PCRNET_ERROR_NO_LK_SOLVER = -44,
    /// An error this version of the C API has no code for (a newer core).
    PCRNET_ERROR_OTHER = -99,
}

impl From<Error> for PcrnetStatus {
    fn from(e: Error) -> Self {
        match e {
            Error::BadMagic => PCRNET_ERROR_BAD_MAGIC,
            Error::UnsupportedVersion { .. } => PCRNET_ERROR_UNSUPPORTED_VERSION,
            Error::WrongKind { .. } => PCRNET_ERROR_WRONG_KIND,
            Error::Truncated { .. } => PCRNET_ERROR_TRUNCATED,
            Error::TrailingData { .. } => PCRNET_ERROR_TRAILING_DATA,
            Error::BadCrc { .. } => PCRNET_ERROR_BAD_CRC,
            Error::Malformed => PCRNET_ERROR_MALFORMED,
            Error::InconsistentDimensions { .. } => PCRNET_ERROR_INCONSISTENT_DIMENSIONS,
            Error::InvalidParameter { .. } => PCRNET_ERROR_INVALID_PARAMETER,
            Error::ScratchTooSmall { .. } => PCRNET_ERROR_SCRATCH_TOO_SMALL,
            Error::BufferTooSmall { .. } => PCRNET_ERROR_BUFFER_TOO_SMALL,
            Error::EmptyCloud => PCRNET_ERROR_EMPTY_CLOUD,
            Error::NonFiniteCoordinate { .. } => PCRNET_ERROR_NON_FINITE_COORDINATE,
            Error::NoPointInRange => PCRNET_ERROR_NO_POINT_IN_RANGE,
            Error::DegeneratePose => PCRNET_ERROR_DEGENERATE_POSE,
            Error::NonFiniteResult => PCRNET_ERROR_NON_FINITE_RESULT,
            Error::InvalidOption { .. } => PCRNET_ERROR_INVALID_OPTION,
            Error::InvalidPose => PCRNET_ERROR_INVALID_POSE,
            Error::InvalidFrame { .. } => PCRNET_ERROR_INVALID_FRAME,
            Error::NoHead => PCRNET_ERROR_NO_HEAD,
            Error::NoLkSolver => PCRNET_ERROR_NO_LK_SOLVER,
            _ => PCRNET_ERROR_OTHER,
        }
    }
}

/// `PcrnetOptions::metric`: point-to-point ICP.
pub const PCRNET_METRIC_POINT_TO_POINT: u32 = 0;
/// `PcrnetOptions::metric`: point-to-plane ICP (the default).
pub const PCRNET_METRIC_POINT_TO_PLANE: u32 = 1;

/// How to register (`pcrnet_core::Options`; distances in model units,
/// i.e. shares of the template's size). Start from
/// `pcrnet_options_default` and change what you need.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcrnetOptions {
    /// Network passes (1: PCRNet; more: i-PCRNet; 0 for a blob without a
    /// head, a model trained as PointNetLK).
    pub passes: u32,
    /// Passes and LK steps stop once one moves the pose by less than this (0: never).
    pub tolerance: f32,
    /// Starting poses of flip resolution, 1 up to 1 + the blob's turns.
    pub hypotheses: u32,
    /// ICP iterations every start gets before the two best continue (a
    /// turned start far above the best after 3 of them is dropped).
    pub screen_iterations: u32,
    /// Most ICP iterations in all (0: no refinement).
    pub icp_iterations: u32,
    /// `PCRNET_METRIC_POINT_TO_PLANE` or `PCRNET_METRIC_POINT_TO_POINT`.
    pub metric: u32,
    /// ICP stops once an update moves the pose by less than this.
    pub icp_tolerance: f32,
    /// ICP leaves out pairs farther apart than this.
    pub icp_distance: f32,
    /// Residuals count a point at most this far; fitness counts points within it.
    pub inlier_distance: f32,
    /// Most source points scored and refined (every k-th point is used).
    pub max_points: u32,
    /// `reliable` when the relative plane residual is at most this.
    pub max_residual: f32,
    /// PointNetLK steps after the network's passes (0: none; needs a blob
    /// with PointNetLK's solver). Refine by LK: this with `icp_iterations`
    /// 0 and one hypothesis; LK then ICP: both.
    pub lk_iterations: u32,
    /// Most source points each network pass and LK step encodes (every
    /// k-th point; at least 1). The default 128 (a blob with a head; 256
    /// for a PointNetLK blob, which `pcrnet_options_for_model` sets) is a
    /// quarter of the network's cost at 512 points with the same accuracy;
    /// exported template features are pooled over that many of the
    /// template's points, so other values pool the two compared features
    /// over different counts.
    pub network_points: u32,
}

impl From<Options> for PcrnetOptions {
    fn from(o: Options) -> Self {
        let count = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        PcrnetOptions {
            passes: count(o.passes),
            tolerance: o.tolerance,
            hypotheses: count(o.hypotheses),
            screen_iterations: count(o.screen_iterations),
            icp_iterations: count(o.icp_iterations),
            metric: match o.metric {
                Metric::PointToPoint => PCRNET_METRIC_POINT_TO_POINT,
                Metric::PointToPlane => PCRNET_METRIC_POINT_TO_PLANE,
            },
            icp_tolerance: o.icp_tolerance,
            icp_distance: o.icp_distance,
            inlier_distance: o.inlier_distance,
            max_points: count(o.max_points),
            max_residual: o.max_residual,
            lk_iterations: count(o.lk_iterations),
            network_points: count(o.network_points),
        }
    }
}

impl TryFrom<&PcrnetOptions> for Options {
    type Error = PcrnetStatus;

    fn try_from(o: &PcrnetOptions) -> Result<Self, PcrnetStatus> {
        let metric = match o.metric {
            PCRNET_METRIC_POINT_TO_POINT => Metric::PointToPoint,
            PCRNET_METRIC_POINT_TO_PLANE => Metric::PointToPlane,
            _ => return Err(PCRNET_ERROR_INVALID_OPTION),
        };
        Ok(Options {
            passes: o.passes as usize,
            lk_iterations: o.lk_iterations as usize,
            network_points: o.network_points as usize,
            tolerance: o.tolerance,
            hypotheses: o.hypotheses as usize,
            screen_iterations: o.screen_iterations as usize,
            icp_iterations: o.icp_iterations as usize,
            metric,
            icp_tolerance: o.icp_tolerance,
            icp_distance: o.icp_distance,
            inlier_distance: o.inlier_distance,
            max_points: o.max_points as usize,
            max_residual: o.max_residual,
        })
    }
}

/// `PcrnetRegistration::degenerate`: the source determines a pose.
pub const PCRNET_DEGENERATE_NONE: u32 = 0;
/// `PcrnetRegistration::degenerate`: all points (nearly) coincide.
pub const PCRNET_DEGENERATE_POINT: u32 = 1;
/// `PcrnetRegistration::degenerate`: the points (nearly) lie on a line.
pub const PCRNET_DEGENERATE_LINE: u32 = 2;

/// What a registration found and how far to trust it
/// (`pcrnet_core::Registration`): `p_template = R p_source + t`, in the
/// source's units.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PcrnetRegistration {
    /// Unit quaternion `[w, x, y, z]`, `w >= 0`.
    pub rotation: [f32; 4],
    /// Translation `[x, y, z]`, source units.
    pub translation: [f32; 3],
    /// Mean distance to the nearest template point (capped), source units.
    pub residual: f32,
    /// The same as a share of the template's size.
    pub relative_residual: f32,
    /// Mean distance to the tangent plane at the nearest template point (capped), source units.
    pub plane_residual: f32,
    /// The same as a share of the template's size: what `reliable` is judged on.
    pub relative_plane_residual: f32,
    /// Share of used source points within the inlier distance.
    pub fitness: f32,
    /// RMS distance of those inliers, source units.
    pub inlier_rmse: f32,
    /// Winning start: 0 the network's pose, `k` it followed by turn `k - 1`.
    pub hypothesis: u32,
    /// Network passes run.
    pub passes: u32,
    /// PointNetLK steps run after them.
    pub lk_iterations: u32,
    /// ICP iterations from the winning start.
    pub icp_iterations: u32,
    /// int8 values that reached the top of their range.
    pub saturated: u32,
    /// Points of the network's sample (`network_points`) left out of it:
    /// outside the model's input range (stray points far from the object).
    pub out_of_range: u32,
    /// `PCRNET_DEGENERATE_NONE`, `_POINT` or `_LINE`.
    pub degenerate: u32,
    /// With `has_free_axis`: the unit direction (sign arbitrary) of an
    /// axis, template frame, about which a rotation barely changes the fit:
    /// the pose's angle about it is arbitrary (a continuous symmetry).
    pub free_axis: [f32; 3],
    /// With `has_free_axis`: the axis's point nearest the template's
    /// centroid, template frame, source units.
    pub free_axis_point: [f32; 3],
    /// With `has_free_axis`: how stiff the fit is to a rotation about it
    /// (below 0.12; 0 is perfectly free).
    pub free_axis_stiffness: f32,
    /// With `has_turn`: the rotation (unit quaternion `[w, x, y, z]`) of
    /// the rigid motion of the template's frame taking the pose to another
    /// that fits about as well (`other = turn after pose`; a discrete symmetry).
    pub turn_rotation: [f32; 4],
    /// With `has_turn`: that motion's translation, source units.
    pub turn_translation: [f32; 3],
    /// With `has_turn`: the turn's angle, degrees (0..=180).
    pub turn_degrees: f32,
    /// With `has_turn`: the other pose's relative plane residual.
    pub turn_relative_plane_residual: f32,
    /// Not degenerate and the relative plane residual within `max_residual`.
    pub reliable: bool,
    /// A free rotation axis was found (`free_axis`, `free_axis_point`,
    /// `free_axis_stiffness`; zero without one).
    pub has_free_axis: bool,
    /// A turn to another pose that fits about as well was found
    /// (`turn_rotation`, `turn_translation`, `turn_degrees`,
    /// `turn_relative_plane_residual`; zero without one).
    pub has_turn: bool,
}

impl From<&Registration> for PcrnetRegistration {
    fn from(r: &Registration) -> Self {
        let count = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        let (axis, turn) = (r.ambiguity.axis, r.ambiguity.turn);
        PcrnetRegistration {
            rotation: r.pose.rotation,
            translation: r.pose.translation,
            residual: r.residual,
            relative_residual: r.relative_residual,
            plane_residual: r.plane_residual,
            relative_plane_residual: r.relative_plane_residual,
            fitness: r.fitness,
            inlier_rmse: r.inlier_rmse,
            hypothesis: count(r.hypothesis),
            passes: count(r.passes),
            lk_iterations: count(r.lk_iterations),
            icp_iterations: count(r.icp_iterations),
            saturated: r.saturated,
            out_of_range: r.out_of_range,
            degenerate: match r.degenerate {
                None => PCRNET_DEGENERATE_NONE,
                Some(Degeneracy::Point) => PCRNET_DEGENERATE_POINT,
                Some(Degeneracy::Line) => PCRNET_DEGENERATE_LINE,
            },
            free_axis: axis.map_or([0.0; 3], |a| a.direction),
            free_axis_point: axis.map_or([0.0; 3], |a| a.point),
            free_axis_stiffness: axis.map_or(0.0, |a| a.stiffness),
            turn_rotation: turn.map_or([0.0; 4], |t| t.motion.rotation),
            turn_translation: turn.map_or([0.0; 3], |t| t.motion.translation),
            turn_degrees: turn.map_or(0.0, |t| t.degrees),
            turn_relative_plane_residual: turn.map_or(0.0, |t| t.relative_plane_residual),
            reliable: r.reliable,
            has_free_axis: axis.is_some(),
            has_turn: turn.is_some(),
        }
    }
}
