//! The two facts a blob's header states that errors name too: the format
//! version ([`FORMAT_VERSION`]) and the kind of model ([`ModelKind`]).
//! They sit here, below both [`crate::error`] and [`crate::format`] (which
//! re-exports them), so that neither module imports the other's.

/// Format version written and read by this build.
pub const FORMAT_VERSION: u16 = 7;
/// The oldest format version this build reads (format 3: no closest-point
/// table; the template's grid is searched instead, with the same results).
pub const OLDEST_READABLE: u16 = 3;

/// What the payload holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelKind {
    /// Quantized int8 network for the device ([`crate::format::Int8Payload`]).
    Int8 = 0,
    /// f32 reference network ([`crate::format::F32Payload`]).
    F32 = 1,
}
