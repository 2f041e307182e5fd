//! A model made ready for many calls on one scratch: the host's per-model
//! work done once instead of once per call.

use super::{Int8Inference, Int8Model, Ready};
use crate::error::Result;
use crate::pose::Pose;
use crate::registration::{Options, Registration};

/// An [`Int8Model`] with a scratch it has made ready
/// ([`Int8Model::prepare`]): calls on it give the model's own results, bit
/// for bit, without redoing what depends on the model alone.
///
/// On a host with a block kernel (`std` feature; x86-64 with AVX2,
/// aarch64 with the dot-product extension) and
/// [`Int8Model::host_scratch_len`] bytes of scratch, preparing
/// - copies the encoder weights the block kernel reads (int16 rows of
///   the first layer, and every layer's on AVX2 but a pooled one on bytes)
///   and each row's weight sum, which a call on the model itself redoes
///   every time;
/// - folds the template half of the head's first layer into its biases:
///   the template feature is fixed by the blob, so output `o`'s
///   `bias + W[o][..F] . template` is one i32, exact, and each call reads
///   only the source half of that layer's weights (`F x width` bytes
///   fewer: 1 MB at the paper's widths, a quarter of the head).
///
/// Anywhere else (a device, a host without those kernels, a shorter
/// scratch) nothing is prepared and the calls are the model's own.
///
/// Sources, poses, units and errors are those of the model's methods of
/// the same names. The scratch stays borrowed, so nothing else can write
/// into what was prepared; the weights stay in the blob.
pub struct Prepared<'m, 'a, 's> {
    model: &'m Int8Model<'a>,
    scratch: &'s mut [i8],
    tile: usize,
    ready: Ready,
}

impl core::fmt::Debug for Prepared<'_, '_, '_> {
    /// The model, the scratch's length (not its bytes), the tile and what
    /// was prepared.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Prepared")
            .field("model", self.model)
            .field("scratch_len", &self.scratch.len())
            .field("tile", &self.tile)
            .field("ready", &self.ready)
            .finish()
    }
}

impl<'a> Int8Model<'a> {
    /// Makes `scratch` ready for many calls of this model (see
    /// [`Prepared`]); [`Int8Model::host_scratch_len`] bytes let a host
    /// prepare everything, and at least [`Int8Model::scratch_len`]`(1)`
    /// are needed ([`crate::Error::ScratchTooSmall`] otherwise).
    pub fn prepare<'m, 's>(&'m self, scratch: &'s mut [i8]) -> Result<Prepared<'m, 'a, 's>> {
        let tile = self.tile_for(scratch.len())?;
        #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
        let ready = {
            use crate::kernel::block::BlockEncoder;
            let (_, _, extra) = self.split_scratch(tile, scratch)?;
            let (block, folded) = self.split_host(extra);
            Ready {
                block: BlockEncoder::prepare(&self.p.arch, &self.p.encoder, block),
                folded: self.fold_template(folded),
            }
        };
        #[cfg(not(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std")))]
        let ready = Ready::default();
        Ok(Prepared {
            model: self,
            scratch,
            tile,
            ready,
        })
    }
}

impl<'a> Prepared<'_, 'a, '_> {
    /// The model.
    pub fn model(&self) -> &Int8Model<'a> {
        self.model
    }

    /// [`Int8Model::register`] on the prepared scratch.
    pub fn register(&mut self, source: &[[f32; 3]], options: &Options) -> Result<Registration> {
        self.model
            .register_ready(source, options, self.tile, self.scratch, self.ready)
    }

    /// [`Int8Model::network_pose`] on the prepared scratch.
    pub fn network_pose(
        &mut self,
        source: &[[f32; 3]],
        passes: usize,
        tolerance: f32,
    ) -> Result<(Pose, usize)> {
        let (tile, ready) = (self.tile, self.ready);
        self.model
            .network_pose_ready(source, passes, tolerance, tile, self.scratch, ready)
    }

    /// [`Int8Model::infer`] on the prepared scratch (the feature a view
    /// into it).
    pub fn infer(&mut self, source: &[[f32; 3]]) -> Result<Int8Inference<'_>> {
        self.model
            .infer_ready(source, self.tile, self.scratch, self.ready)
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::arch::MAX_TILE;
    use crate::format::Frame;
    use crate::testing::{SplitMix64, random_cloud, random_int8_blob_with};
    use std::vec;

    /// On random models (a head with hidden layers and one without;
    /// features that are and are not multiples of 16 and 64; centring on
    /// and off) and clouds from 1 to 1,000 points, some of them past the
    /// input range, a prepared scratch gives the model's own inference,
    /// network pose and registration, bit for bit; with the host's whole
    /// scratch, without room for the folded biases, and with a device's.
    /// Where the CPU has a block kernel, preparing the whole host scratch
    /// must have prepared both parts, so the comparison is not vacuous.
    #[test]
    fn prepared_calls_match_the_model() {
        let host = crate::kernel::block::has_route();
        if !host {
            std::eprintln!("no block kernel on this CPU: nothing is prepared");
        }
        let shapes: [(&[u16], &[u16], bool); 4] = [
            (&[16, 24, 64], &[48, 32], true),
            (&[32, 32, 128, 256], &[64], false),
            (&[7, 33, 65], &[16], true),
            (&[8], &[], false),
        ];
        let options = Options {
            hypotheses: 3,
            icp_iterations: 5,
            ..Options::default()
        };
        let mut registered = 0;
        for (seed, (enc, head, centre)) in (1u64..).zip(shapes) {
            let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
            let frame = Frame::IDENTITY;
            let blob = random_int8_blob_with(seed, enc, head, centre, frame, &mut arena, &mut out)
                .unwrap();
            let model = Int8Model::from_bytes(blob).unwrap();
            let full = model.host_scratch_len();
            let folded = model.folded_len();
            for len in [full, full - folded, model.scratch_len(MAX_TILE)] {
                let mut scratch = vec![0i8; len];
                let mut prepared = model.prepare(&mut scratch).unwrap();
                if host && len == full {
                    assert!(prepared.ready.block, "{prepared:?}");
                    assert_eq!(prepared.ready.folded, !head.is_empty(), "{prepared:?}");
                }
                let mut plain = vec![0i8; len];
                let mut rng = SplitMix64(seed);
                for n in [1usize, 9, 64, 95, 1000] {
                    let mut cloud: [[f32; 3]; 1000] = random_cloud(&mut rng);
                    if n > 1 {
                        cloud[0] = [40.0, 0.0, 0.0];
                    }
                    let cloud = &cloud[..n];
                    let what = std::format!("seed {seed}, scratch {len}, {n} points");
                    let want = model.infer(cloud, &mut plain).unwrap();
                    let (feature, head, counts) = (
                        want.feature.to_vec(),
                        want.head,
                        (want.saturated, want.out_of_range),
                    );
                    let got = prepared.infer(cloud).unwrap();
                    assert_eq!(got.feature, &feature[..], "feature, {what}");
                    assert_eq!(got.head, head, "head, {what}");
                    assert_eq!((got.saturated, got.out_of_range), counts, "counts, {what}");
                    let pose = prepared.network_pose(cloud, 3, 0.0);
                    assert_eq!(
                        pose,
                        model.network_pose(cloud, 3, 0.0, &mut plain),
                        "network pose, {what}"
                    );
                    let registration = prepared.register(cloud, &options);
                    assert_eq!(
                        registration,
                        model.register(cloud, &options, &mut plain),
                        "registration, {what}"
                    );
                    registered += usize::from(pose.is_ok() && registration.is_ok());
                }
            }
        }
        // Most calls succeed (an error is compared as well, but says less).
        assert!(registered >= 40, "{registered} of 60 calls succeeded");
    }
}
