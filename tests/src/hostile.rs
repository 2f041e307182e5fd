//! Blobs the loader must judge the same way on the device as on the host.
//!
//! Each goes into the container as a model without cases: the runner
//! prints its load verdict ([`load_verdict`]) and the host compares it with
//! its own. Sizes in a blob are combined with checked arithmetic, so a
//! product that fits a 64-bit `usize` but wraps a 32-bit one must be
//! refused on both (issue 14: an f32 head of 131,070 x 32,769 weights,
//! 65,534 after wrapping, used to load on the device).

use pcrnet_core::format::{self, F32Layer, F32Payload, ModelKind};
use pcrnet_core::testing::random_f32_blob_into;
use pcrnet_core::{Error, F32Model, Int8Model};

use crate::vectors::TestModel;

/// What loading `blob` gives: `ok int8`, `ok f32` (an int8 load that finds
/// an f32 blob tries the f32 loader), or `error <Debug of the error>`.
/// The device runner prints the same words.
pub fn load_verdict(blob: &[u8]) -> String {
    match Int8Model::from_bytes(blob) {
        Ok(_) => "ok int8".into(),
        Err(Error::WrongKind { .. }) => match F32Model::from_bytes(blob) {
            Ok(_) => "ok f32".into(),
            Err(e) => format!("error {e:?}"),
        },
        Err(e) => format!("error {e:?}"),
    }
}

/// The hostile blobs, named for the report.
pub fn blobs() -> anyhow::Result<Vec<TestModel>> {
    Ok(vec![TestModel {
        name: "f32 head 131070 x 32769 (65534 when wrapped to 32 bits)".into(),
        blob: wrapping_f32_head()?,
    }])
}

/// An f32 blob whose first head layer claims `2 x 65,535` inputs and
/// 32,769 outputs but holds 65,534 weights: `131,070 x 32,769 =
/// 4,295,032,830 = 2^32 + 65,534`. Every other size is right (2.3 MB).
fn wrapping_f32_head() -> anyhow::Result<Vec<u8>> {
    const FEATURE: u16 = 65_535;
    const HEAD: u16 = 32_769;
    // A valid small f32 blob lends its template cloud and frame.
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    let small = random_f32_blob_into(9, &[8], &[], &mut arena, &mut out)
        .map_err(|e| anyhow::anyhow!("small f32 blob: {e:?}"))?;
    let (base, _): (F32Payload<'_>, _) =
        format::decode_model(small, ModelKind::F32).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let (f, h) = (FEATURE as usize, HEAD as usize);
    let floats = |n: usize| vec![0u8; 4 * n];
    let (enc_w, enc_b) = (floats(3 * f), floats(f));
    let wrapped = (2 * f as u64 * h as u64) % (1 << 32);
    let (head_w, head_b) = (floats(wrapped as usize), floats(h));
    let (out_w, out_b) = (floats(7 * h), floats(7));
    let template_feature = floats(f);
    let mut layers = heapless::Vec::new();
    for (weights, bias) in [(&enc_w, &enc_b), (&head_w, &head_b), (&out_w, &out_b)] {
        layers
            .push(F32Layer { weights, bias })
            .map_err(|_| anyhow::anyhow!("too many layers"))?;
    }
    let payload = F32Payload {
        arch: pcrnet_core::Arch::new(&[FEATURE], &[HEAD]).map_err(|e| anyhow::anyhow!("{e:?}"))?,
        layers,
        template_feature: &template_feature,
        ..base
    };
    let mut blob = vec![
        0u8;
        format::blob_len(&payload, &format::Trailer::default())
            .map_err(|e| anyhow::anyhow!("{e:?}"))?
    ];
    let n = format::write_blob(
        ModelKind::F32,
        &payload,
        &format::Trailer::default(),
        &mut blob,
    )
    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    blob.truncate(n);
    Ok(blob)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wrapping_head_is_refused_on_the_host() {
        let blob = wrapping_f32_head().unwrap();
        assert_eq!(
            load_verdict(&blob),
            "error InconsistentDimensions { what: \"layer weights\" }"
        );
    }
}
