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
use pcrnet_core::format::{CRC_LEN, F32Layer, HEADER_LEN, MAGIC, ModelKind};

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
    /// Not a format-2 f32 blob.
    #[error(
        "not a format-2 f32 blob (magic, version 2 and kind f32 expected; found version {version}, kind {kind}); only f32 blobs carry the weights an upgrade needs"
    )]
    NotV2F32 {
        /// Version found.
        version: u16,
        /// Kind byte found.
        kind: u8,
    },
    /// Truncated, CRC mismatch or a payload that does not decode.
    #[error("the format-2 blob is damaged: {0}")]
    Damaged(&'static str),
    /// The weights do not fit the architecture.
    #[error("pcrnet-core: {0}")]
    Core(#[from] pcrnet_core::Error),
}

/// The network of a format-2 f32 blob: its parameters and whether it centres sources.
pub fn read_v2_f32(blob: &[u8]) -> Result<(F32Params, bool), UpgradeError> {
    if blob.len() < HEADER_LEN + CRC_LEN || blob[..4] != MAGIC {
        return Err(UpgradeError::Damaged("too short or no `PCRN` magic"));
    }
    let version = u16::from_le_bytes([blob[4], blob[5]]);
    if version != 2 || blob[6] != ModelKind::F32 as u8 {
        return Err(UpgradeError::NotV2F32 {
            version,
            kind: blob[6],
        });
    }
    let len = u32::from_le_bytes([blob[7], blob[8], blob[9], blob[10]]) as usize;
    if blob.len() != HEADER_LEN + len + CRC_LEN {
        return Err(UpgradeError::Damaged("length does not match the header"));
    }
    let (body, crc) = blob.split_at(HEADER_LEN + len);
    let stored = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if stored != crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(body) {
        return Err(UpgradeError::Damaged("CRC mismatch"));
    }
    let payload: F32PayloadV2<'_> = match postcard::take_from_bytes(&body[HEADER_LEN..]) {
        Ok((p, [])) => p,
        _ => return Err(UpgradeError::Damaged("payload does not decode")),
    };
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
