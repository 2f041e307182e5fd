//! Upgrading older blobs to the current format: `pcrnet upgrade`.
//!
//! A format-3 blob of either kind differs from format 4 only in lacking
//! the template's closest-point table ([`add_table`]): its payload is kept
//! byte for byte and the table is built from its stored template, and it
//! is written in the current format (7: no PointNetLK solver, `pcrnet
//! export --lk` makes one from a checkpoint; no residual floor, which needs
//! the object's other points; no up axis, `pcrnet export --up` records
//! one). Blobs of formats 4 to 6 need nothing: this build reads them as
//! they are.
//!
//! A format-2 f32 blob (before frames and template points) needs its
//! template recorded afresh.
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
use pcrnet_core::format::{self, F32Layer, F32Payload, Int8Payload, ModelKind, write_blob};
use pcrnet_core::template::Template;

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
    /// Already a format this build reads with its closest-point table.
    #[error(
        "the blob is format {0}, which this build reads as it is (with its closest-point table): nothing to upgrade"
    )]
    Current(u16),
    /// A format-3 blob that does not decode.
    #[error("not a sound format-3 blob")]
    DamagedFormat3(#[source] pcrnet_core::Error),
    /// Its template's closest-point table could not be built.
    #[error("building the template's closest-point table")]
    Table(#[source] crate::template::TemplateError),
    /// The blob is of another format.
    #[error(
        "the blob is format {found}, not 2: only format-2 f32 blobs are exported afresh (a format-3 blob gains its closest-point table; formats 4 to {current} read as they are)"
    )]
    NotFormat2 {
        /// The format found.
        found: u16,
        /// The current format (`FORMAT_VERSION`).
        current: u16,
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
            pcrnet_core::Error::UnsupportedVersion { found } => UpgradeError::NotFormat2 {
                found,
                current: format::FORMAT_VERSION,
            },
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

/// The format-3 blob `blob` (int8 or f32) in the current format: the same
/// payload and the template's [`crate::template::DEFAULT_TABLE`]
/// closest-point table. Returns the kind and the new blob.
pub fn add_table(blob: &[u8]) -> Result<(ModelKind, Vec<u8>), UpgradeError> {
    let found = blob
        .get(4..6)
        .map_or(0, |v| u16::from_le_bytes([v[0], v[1]]));
    if (4..=format::FORMAT_VERSION).contains(&found) {
        return Err(UpgradeError::Current(found));
    }
    let damaged = UpgradeError::DamagedFormat3;
    let table = |cloud: &format::TemplateCloud<'_>| {
        let t = Template::new(cloud.clone(), None).map_err(damaged)?;
        crate::template::OwnedTable::build(&t, crate::template::DEFAULT_TABLE)
            .map_err(UpgradeError::Table)
    };
    match format::open_version(blob, ModelKind::Int8, 3) {
        Ok(body) => {
            let p: Int8Payload<'_> = format::decode(body).map_err(damaged)?;
            with_table(ModelKind::Int8, &p, &table(&p.template)?)
        }
        Err(pcrnet_core::Error::WrongKind { .. }) => {
            let body = format::open_version(blob, ModelKind::F32, 3).map_err(damaged)?;
            let p: F32Payload<'_> = format::decode(body).map_err(damaged)?;
            with_table(ModelKind::F32, &p, &table(&p.template)?)
        }
        Err(e) => Err(damaged(e)),
    }
}

/// A current blob of `payload` and `table`.
fn with_table(
    kind: ModelKind,
    payload: &impl serde::Serialize,
    table: &crate::template::OwnedTable,
) -> Result<(ModelKind, Vec<u8>), UpgradeError> {
    let trailer = format::Trailer {
        table: Some(table.view()),
        ..format::Trailer::default()
    };
    let mut out =
        vec![0u8; format::blob_len(payload, &trailer).map_err(UpgradeError::DamagedFormat3)?];
    write_blob(kind, payload, &trailer, &mut out).map_err(UpgradeError::DamagedFormat3)?;
    Ok((kind, out))
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
        assert!(matches!(e, UpgradeError::NotFormat2 { found: 4, .. }));
        assert!(e.to_string().contains("format 4, not 2"), "{e}");
    }

    /// The shipped blob under format 3's header (its payload alone).
    fn as_format_3(blob: &[u8], kind: ModelKind) -> Vec<u8> {
        let body = format::open_version(blob, kind, 4).unwrap();
        let (payload_len, table_len) = match kind {
            ModelKind::Int8 => {
                let (_, rest) = postcard::take_from_bytes::<Int8Payload<'_>>(body).unwrap();
                (body.len() - rest.len(), rest.len())
            }
            ModelKind::F32 => {
                let (_, rest) = postcard::take_from_bytes::<F32Payload<'_>>(body).unwrap();
                (body.len() - rest.len(), rest.len())
            }
        };
        assert!(table_len > 1000, "the shipped blob carries a table");
        let mut v3 = MAGIC.to_vec();
        v3.extend_from_slice(&3u16.to_le_bytes());
        v3.push(kind as u8);
        v3.extend_from_slice(&(payload_len as u32).to_le_bytes());
        v3.extend_from_slice(&body[..payload_len]);
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&v3);
        v3.extend_from_slice(&crc.to_le_bytes());
        v3
    }

    /// A format-3 blob of either kind gains the default table and nothing
    /// else: the shipped blobs (format 4) are their format-3 forms
    /// upgraded, the same payload and table (the current format adds only
    /// an empty PointNetLK slot, an empty residual floor and an empty up
    /// axis).
    #[test]
    fn format_3_blobs_gain_their_table() {
        let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
        for (name, kind) in [
            ("embedded-default-int8.pcrn", ModelKind::Int8),
            ("embedded-default-f32.pcrn", ModelKind::F32),
        ] {
            let shipped = std::fs::read(models.join(name)).unwrap();
            let old = as_format_3(&shipped, kind);
            let (found, upgraded) = add_table(&old).unwrap();
            assert_eq!(found, kind);
            let new = format::open_version(&upgraded, kind, format::FORMAT_VERSION).unwrap();
            let old4 = format::open_version(&shipped, kind, 4).unwrap();
            // Payload and table byte for byte, then `None` for the solver,
            // the residual floor and the up axis.
            assert!(
                new[..new.len() - 3] == *old4 && new[new.len() - 3..] == [0, 0, 0],
                "{name}: upgrade differs from the shipped blob"
            );
            assert!(matches!(add_table(&shipped), Err(UpgradeError::Current(4))));
            let mut damaged = old.clone();
            damaged[HEADER_LEN + 5] ^= 1;
            assert!(matches!(
                add_table(&damaged),
                Err(UpgradeError::DamagedFormat3(
                    pcrnet_core::Error::BadCrc { .. }
                ))
            ));
        }
    }
}
