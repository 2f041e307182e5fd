//! # pcrnet-train
//!
//! The host side of the project: f32 PCRNet parameters, post-training
//! quantization to `pcrnet-core`'s int8 format, and export of both blobs.
//! Training (issue 3) builds on these pieces.
//!
//! The forward pass is `pcrnet-core`'s own f32 path ([`pcrnet_core::float`]),
//! run over the arrays held here, so host and device share one network
//! definition.

pub mod net;
pub mod quantize;
pub mod shapes;

pub use net::F32Params;
pub use quantize::{CalibrationRule, QuantizeError, quantize};
