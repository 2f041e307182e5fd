//! # pcrnet-core
//!
//! `no_std`, allocation-free point cloud registration with a quantized
//! PointNet encoder and a PCRNet pose head (Sarode et al., *One Framework to
//! Register Them All*, AAAI 2020), for microcontrollers.
//!
//! Data flows **points -> quantize -> encode -> head -> pose -> check/refine**:
//!
//! | step | where | what |
//! |---|---|---|
//! | points | caller | `&[[f32; 3]]` in the user's units and axes, any count from 1 |
//! | frame | [`Frame`] (blob) | into the model frame: `scale (p - centre)` |
//! | quantize | [`fixed::quantize_coordinate`] | int16 coordinates, scale stored in the model |
//! | encode | [`Int8Model::encode`] | per-point MLP, streamed in tiles, running max-pool -> int8 feature |
//! | head | [`Int8Model::head`] | FC layers over (template feature, source feature) -> 7 i32 |
//! | pose | [`Pose::from_head_output`] | unit quaternion + translation (f32, `libm`) |
//! | (PointNetLK) | [`lk`] | instead of or after the head: Lucas-Kanade steps in feature space, a solver stored in the blob |
//! | check/refine | [`registration`], [`refine`] | flip hypotheses, ICP against the template's points, residual -> [`Registration`] |
//!
//! The model is a blob ([`format`]) whose weights are used in place (flash),
//! and all working memory is a caller-owned scratch slice, so the crate
//! never allocates. Sizes are known up front: [`scratch_len_for`] reads
//! them from the blob's bytes in a `const` ([`int8_scratch_len`] from the
//! layer widths).
//!
//! ```
//! # fn main() -> Result<(), pcrnet_core::Error> {
//! # let (mut arena, mut out) = ([0u8; 16384], [0u8; 16384]);
//! # let blob = pcrnet_core::testing::random_int8_blob_into(7, &[16, 32], &[32], &mut arena, &mut out)?;
//! use pcrnet_core::{Int8Model, Options, int8_scratch_len};
//!
//! // Sized at compile time for the architecture (here encoder 16-32, head 32, tile 8).
//! const SCRATCH: usize = int8_scratch_len(&[16, 32], &[32], 8);
//! let mut scratch = [0i8; SCRATCH];
//!
//! let model = Int8Model::load(blob, &scratch)?; // checks magic, version, CRC, sizes, scratch
//! let source = [[0.1, 0.2, 0.3], [0.0, -0.1, 0.25], [-0.2, 0.05, 0.0]];
//! let result = model.register(&source, &Options::default(), &mut scratch)?;
//! let m = result.pose.matrix(); // 4x4, maps the source onto the template, user units
//! if !result.reliable {
//!     // residual too high or a degenerate source: do not act on this pose
//! }
//! # let _ = (m, result.residual, result.fitness);
//! # Ok(())
//! # }
//! ```
//!
//! The f32 reference of the same network is [`F32Model`] (blob kind
//! `F32`), or [`float::F32Network`] over the trainer's own arrays.
//!
//! [`Int8Model::network_pose`] is the network alone (no check, no
//! refinement); [`Int8Model::infer`], [`Int8Model::encode`] and
//! [`Int8Model::head`] expose the raw feature and head outputs. On a host
//! calling one model many times, [`Int8Model::prepare`] makes a scratch
//! ready once ([`Prepared`]: the same results, less work per call).
//!
//! ## Guarantees
//! - No allocation, no panic reachable from any blob or any cloud: every
//!   failure is an [`Error`]. Proven at link time for the release
//!   Cortex-M builds (`cargo xtask no-panic`: an image calling every entry
//!   point on inputs the optimiser cannot see, whose panic handler cannot
//!   link); fuzzed on the host (`cargo xtask fuzz`).
//! - Blob sizes are combined with checked arithmetic, so a blob loads or
//!   fails the same way on 32- and 64-bit targets (checked under QEMU).
//! - The int8 path is integer-only up to the head output; the pose uses
//!   single f32 operations and `libm`, so the device and the host agree bit
//!   for bit. So does refinement: the nearest-neighbour search and the
//!   point-to-point sums are integers, the point-to-plane system, the
//!   eigen-solver and the scores are f32 in a fixed order with `libm`
//!   (checked on 186 registrations under QEMU).
//! - Refinement's memory does not depend on the number of points: it uses
//!   no scratch (running sums, the blob's own search grid).
//! - A pose, residual, f32 feature or f32 head output is never NaN or
//!   infinite: such a result is [`Error::NonFiniteResult`].
//! - Encoder output is invariant to the order of the points and to the tile
//!   size, bit for bit. For models that centre the source, the centroid is
//!   an f64 sum in point order: exact, hence order-independent, while the
//!   largest coordinate magnitude over the smallest non-zero one stays below
//!   2^29 / N for N points (about 5e5 for 1024 points); beyond that only
//!   exactness is lost, not determinism: the same order gives the same bits.
#![no_std]
#![cfg_attr(docsrs, feature(doc_cfg))]

// Run-time CPU feature detection for the host kernels (`std` feature).
#[cfg(feature = "std")]
extern crate std;

pub mod ambiguity;
pub mod arch;
pub mod eigen;
mod error;
pub mod fixed;
pub mod float;
pub mod follow;
pub mod format;
mod header;
pub mod int8;
mod kernel;
pub mod lk;
pub mod locate;
pub mod pose;
pub mod random;
pub mod refine;
pub mod registration;
pub mod scene;
mod sizes;
pub mod sweep;
pub mod template;
#[doc(hidden)]
pub mod testing;
pub mod track;
pub mod viewed;

pub use ambiguity::{Ambiguity, FreeAxis, Turn};
pub use arch::{Arch, F32_TILE, MAX_TILE, POSE_DIM, f32_scratch_len, int8_scratch_len};
pub use error::{Error, Result};
pub use float::F32Model;
pub use format::Frame;
pub use int8::{Int8Inference, Int8Model, Prepared};
pub use pose::Pose;
pub use refine::{Degeneracy, Metric};
pub use registration::{Options, Registration};
pub use sizes::scratch_len_for;
pub use track::{TrackOutcome, Tracking};
