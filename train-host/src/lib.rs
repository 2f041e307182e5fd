//! # pcrnet-train
//!
//! The host side of the project: f32 PCRNet parameters, post-training
//! quantization to `pcrnet-core`'s int8 format, and export of both blobs.
//! Training (issue 3) builds on these pieces.
//!
//! The forward pass is `pcrnet-core`'s own f32 path ([`pcrnet_core::float`]),
//! run over the arrays held here, so host and device share one network
//! definition.

pub mod eval;
pub mod frame;
pub mod inspect;
pub mod io;
pub mod net;
pub mod progress;
pub mod quantize;
pub mod reduce;
pub mod register;
pub mod shapes;
pub mod template;
pub mod train;
pub mod upgrade;

pub use net::{F32Params, TrainedFor};
pub use quantize::{CalibrationRule, QuantizeError, quantize};

/// Encoder widths of the embedded default (`models/embedded-default-*`):
/// int8 blob 224 KB, 2.3 KB scratch. Not yet chosen by a measured
/// size/accuracy sweep.
pub const EMBEDDED_ENCODER: &[u16] = &[32, 64, 128, 256];
/// Hidden head widths of the embedded default (see above).
pub const EMBEDDED_HEAD: &[u16] = &[256, 128, 64];
