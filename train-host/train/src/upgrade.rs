//! Upgrading a format-2 f32 blob (before frames and template points) to
//! the current format: `pcrnet upgrade`.
//!
//! A version-2 f32 blob holds every weight of the network, so nothing is
//! lost: its weights are read, the template is recorded afresh
//! ([`crate::template::Reference`]), and both blobs are exported as if from
//! a checkpoint (the int8 one re-quantized with seeded calibration clouds).
//! Version-2 int8 blobs cannot be upgraded on their own: their f32 weights
//! are gone; upgrade the f32 blob exported beside them.

use serde::Deserialize;

use pcrnet_core::Arch;
use pcrnet_core::float::LeF32;
use pcrnet_core::format::{self, F32Layer, ModelKind};

use crate::net::F32Params;

/// The format-2 f32 payload, field for field.
#[derive(Deserialize)]
struct F32PayloadV2<'a> {
    arch: Arch,
    centre_source: bool,
    #[serde(borrow)]
    layers: heapless::Vec<F32Layer<'a>, { 2 * pcrnet_core::arch::MAX_LAYERS + 1 }>,
    /// Decoded so the payload is consumed exactly; the feature is recomputed.
    _template_feature: &'a [u8],
}

/// Why a blob cannot be upgraded.
#[derive(Debug, thiserror::Error)]
pub enum UpgradeError {
    /// The blob is of another format.
    #[error(
        "the blob is format {found}, not 2: only format-2 blobs need an upgrade (a format-3 blob is current)"
    )]
    NotFormat2 {
        /// The format found.
        found: u16,
    },
    /// Not a sound format-2 f32 blob (not f32, truncated, CRC mismatch, a
    /// payload that does not decode or does not fit its architecture).
    #[error(
        "not a sound format-2 f32 blob; only f32 blobs can be upgraded: they carry the weights"
    )]
    Damaged(#[source] pcrnet_core::Error),
}

impl From<pcrnet_core::Error> for UpgradeError {
    fn from(e: pcrnet_core::Error) -> Self {
        match e {
            pcrnet_core::Error::UnsupportedVersion { found } => UpgradeError::NotFormat2 { found },
            e => UpgradeError::Damaged(e),
        }
    }
}

/// The network of a format-2 f32 blob: its parameters and whether it centres sources.
pub fn read_v2_f32(blob: &[u8]) -> Result<(F32Params, bool), UpgradeError> {
    let body = format::open_version(blob, ModelKind::F32, 2)?;
    let payload: F32PayloadV2<'_> = format::decode(body)?;
    let layers: heapless::Vec<_, { 2 * pcrnet_core::arch::MAX_LAYERS + 1 }> = payload
        .layers
        .iter()
        .map(|l| pcrnet_core::float::Layer {
            weights: LeF32(l.weights),
            bias: LeF32(l.bias),
        })
        .collect();
    let zeros = vec![0u8; 4 * payload.arch.feature_dim()];
    let net = pcrnet_core::float::F32Network::new(payload.arch, layers, LeF32(&zeros))?;
    Ok((F32Params::from_network(&net), payload.centre_source))
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcrnet_core::format::{CRC_LEN, HEADER_LEN, MAGIC};
    use serde::Serialize;

    /// The format-2 f32 payload as the format-2 exporter wrote it.
    #[derive(Serialize)]
    struct V2<'a> {
        arch: Arch,
        centre_source: bool,
        layers: Vec<F32Layer<'a>>,
        template_feature: &'a [u8],
    }

    fn v2_blob(params: &F32Params) -> Vec<u8> {
        let bytes: Vec<(Vec<u8>, Vec<u8>)> = params
            .layers
            .iter()
            .map(|(w, b)| (crate::net::le_bytes(w), crate::net::le_bytes(b)))
            .collect();
        let feature = vec![0u8; 4 * params.arch.feature_dim()];
        let payload = postcard::to_allocvec(&V2 {
            arch: params.arch.clone(),
            centre_source: true,
            layers: bytes
                .iter()
                .map(|(w, b)| F32Layer {
                    weights: w,
                    bias: b,
                })
                .collect(),
            template_feature: &feature,
        })
        .unwrap();
        let mut blob = MAGIC.to_vec();
        blob.extend_from_slice(&2u16.to_le_bytes());
        blob.push(ModelKind::F32 as u8);
        blob.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        blob.extend_from_slice(&payload);
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&blob);
        blob.extend_from_slice(&crc.to_le_bytes());
        assert_eq!(blob.len(), HEADER_LEN + payload.len() + CRC_LEN);
        blob
    }

    #[test]
    fn reads_format_2_f32_blobs_and_refuses_the_rest() {
        let params = F32Params::init(Arch::new(&[8, 16], &[16]).unwrap(), 4);
        let blob = v2_blob(&params);
        let (back, centre) = read_v2_f32(&blob).unwrap();
        assert_eq!((back, centre), (params, true));
        // A flipped byte fails the CRC; a current blob has the wrong version.
        let mut bad = blob.clone();
        bad[HEADER_LEN + 3] ^= 1;
        assert!(matches!(
            read_v2_f32(&bad),
            Err(UpgradeError::Damaged(pcrnet_core::Error::BadCrc { .. }))
        ));
        let shipped = std::fs::read(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../models/embedded-default-f32.pcrn"),
        )
        .unwrap();
        let e = read_v2_f32(&shipped).unwrap_err();
        assert!(matches!(e, UpgradeError::NotFormat2 { found: 3 }));
        assert!(e.to_string().contains("format 3, not 2"), "{e}");
    }
}
