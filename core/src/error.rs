//! The one error type of the crate.

use core::fmt;

use crate::header::ModelKind;

/// Everything that can go wrong when loading a model or running inference.
///
/// Every fallible function in this crate returns this type; none of them
/// panics. Variants carry just enough context to act on the error without
/// allocating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Error {
    /// The blob does not start with the magic bytes `PCRN`.
    BadMagic,
    /// The blob's format version is not one this build reads.
    UnsupportedVersion {
        /// Version found in the blob.
        found: u16,
    },
    /// The blob holds a different kind of model (e.g. an f32 blob given to the int8 loader).
    WrongKind {
        /// Kind the caller asked for.
        expected: ModelKind,
        /// Raw kind byte found in the blob.
        found: u8,
    },
    /// The blob ends before the length its header announces.
    Truncated {
        /// Bytes the header says the blob has.
        needed: usize,
        /// Bytes actually given.
        available: usize,
    },
    /// Bytes follow the CRC at the end of the blob.
    TrailingData {
        /// Number of unexpected bytes.
        extra: usize,
    },
    /// The CRC-32 stored in the blob does not match its contents.
    BadCrc {
        /// CRC stored in the blob.
        stored: u32,
        /// CRC computed over the blob.
        computed: u32,
    },
    /// The payload passed the CRC but does not decode as a model description.
    Malformed,
    /// Layer sizes in the payload do not agree with the architecture or with each other.
    InconsistentDimensions {
        /// Which part disagrees.
        what: &'static str,
    },
    /// A parameter is outside its documented range (non-finite scale, shift
    /// outside `-31..=31`, bias that could overflow the accumulator, ...).
    InvalidParameter {
        /// Which parameter.
        what: &'static str,
    },
    /// The caller's scratch buffer cannot hold the working memory of this model.
    ScratchTooSmall {
        /// Elements required.
        needed: usize,
        /// Elements provided.
        available: usize,
    },
    /// An output buffer (e.g. for writing a blob) is too small.
    BufferTooSmall {
        /// Bytes required.
        needed: usize,
        /// Bytes provided.
        available: usize,
    },
    /// The point cloud has no points.
    EmptyCloud,
    /// A coordinate is NaN or infinite.
    NonFiniteCoordinate {
        /// Index of the offending point.
        index: usize,
    },
    /// Every point the network encodes (its sample,
    /// [`crate::Options::network_points`]) lies outside the model's int16 input range
    /// (`|x| > 32767 * input_scale` in the model frame, after centring for
    /// models that centre the source). Points outside it are left out of the
    /// network (never clamped, which would move them) and counted in
    /// [`crate::Registration::out_of_range`]; with none left there is no pose.
    NoPointInRange,
    /// The network's quaternion output has zero (or non-finite) norm, so no
    /// rotation can be formed from it.
    DegeneratePose,
    /// A result (pose, residual) came out NaN or infinite: the cloud's
    /// coordinates are too large for f32 arithmetic after the model's frame
    /// is applied. Bring the cloud near the template's frame first.
    NonFiniteResult,
    /// A registration option is outside its range (zero passes, a negative
    /// or non-finite tolerance or distance, ...).
    InvalidOption {
        /// Which option.
        what: &'static str,
    },
    /// A pose given as input (the previous pose of a tracking step) is not
    /// finite or its rotation is not a unit quaternion.
    InvalidPose,
    /// A sensor frame or a scene setting cannot be used: a zero size, a
    /// slice shorter than the frame, intrinsics or a depth scale that are
    /// not finite and positive, a sampling grid too large for its labels.
    InvalidFrame {
        /// What is wrong, and what to change.
        what: &'static str,
    },
    /// A network pass was asked of a blob without a head: a model trained
    /// as PointNetLK, whose pose comes from its LK steps
    /// ([`crate::Options::lk_iterations`], with `passes` 0).
    NoHead,
    /// LK steps were asked of a blob without PointNetLK's solver: export
    /// the model with `pcrnet export --lk`.
    NoLkSolver,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::BadMagic => write!(f, "not a model blob: magic bytes `PCRN` missing"),
            Error::UnsupportedVersion { found } => {
                let (oldest, reads) = (
                    crate::header::OLDEST_READABLE,
                    crate::header::FORMAT_VERSION,
                );
                if found > reads {
                    write!(
                        f,
                        "model format version {found} is newer than this build reads ({reads}): use the pcrnet-core (or pcrnet) that wrote it, or a later one"
                    )
                } else {
                    write!(
                        f,
                        "unsupported model format version {found} (this build reads {oldest} to {reads}); re-export the model with `pcrnet export`, or upgrade a version-2 f32 blob with `pcrnet upgrade`"
                    )
                }
            }
            Error::WrongKind { expected, found } => {
                let wanted = match expected {
                    crate::header::ModelKind::Int8 => "an int8 model",
                    crate::header::ModelKind::F32 => "an f32 model",
                };
                match found {
                    0 => write!(f, "the blob holds an int8 model; this needs {wanted}")?,
                    1 => write!(f, "the blob holds an f32 model; this needs {wanted}")?,
                    _ => write!(f, "the blob holds model kind {found}; this needs {wanted}")?,
                }
                write!(
                    f,
                    " (`pcrnet export` writes both: *-int8.pcrn and *-f32.pcrn)"
                )
            }
            Error::Truncated { needed, available } => {
                write!(f, "model blob truncated: {available} of {needed} bytes")
            }
            Error::TrailingData { extra } => {
                write!(f, "{extra} unexpected bytes after the model blob's CRC")
            }
            Error::BadCrc { stored, computed } => write!(
                f,
                "model blob CRC mismatch: stored {stored:#010x}, computed {computed:#010x}; the blob was damaged or changed after export: copy or flash it again, or re-export it"
            ),
            Error::Malformed => write!(f, "model payload does not decode"),
            Error::InconsistentDimensions { what } => {
                write!(f, "inconsistent model dimensions: {what}")
            }
            Error::InvalidParameter { what } => write!(f, "invalid model parameter: {what}"),
            Error::ScratchTooSmall { needed, available } => write!(
                f,
                "scratch too small: model needs {needed} elements, {available} given"
            ),
            Error::BufferTooSmall { needed, available } => {
                write!(
                    f,
                    "output buffer too small: {needed} bytes needed, {available} given"
                )
            }
            Error::EmptyCloud => write!(f, "point cloud is empty"),
            Error::NonFiniteCoordinate { index } => {
                write!(f, "point {index} has a NaN or infinite coordinate")
            }
            Error::NoPointInRange => write!(
                f,
                "every point lies outside the model's input range (`pcrnet inspect` prints it, in template sizes around the template's frame or the source's centroid): the cloud is in other units than the template, or far from where the template is; bring it into the template's units and frame"
            ),
            Error::DegeneratePose => write!(f, "network output has a zero quaternion"),
            Error::NonFiniteResult => write!(
                f,
                "the pose or residual is not finite: the cloud's coordinates are too large for f32 once moved into the model's frame"
            ),
            Error::InvalidOption { what } => write!(f, "invalid registration option: {what}"),
            Error::InvalidPose => write!(
                f,
                "a pose given as input (a previous pose to track from, a pose to check) is not finite or its rotation is not a unit quaternion: pass the pose a registration or tracking step returned, or register afresh"
            ),
            Error::InvalidFrame { what } => write!(f, "invalid sensor frame: {what}"),
            Error::NoHead => write!(
                f,
                "this blob has no head (a model trained as PointNetLK): set passes to 0 and lk_iterations to its trained count (`pcrnet inspect` prints it)"
            ),
            Error::NoLkSolver => write!(
                f,
                "LK steps need PointNetLK's solver in the blob: export the model with `pcrnet export --lk`, or set lk_iterations to 0"
            ),
        }
    }
}

impl core::error::Error for Error {}

/// Shorthand for `Result<T, pcrnet_core::Error>`.
pub type Result<T> = core::result::Result<T, Error>;
