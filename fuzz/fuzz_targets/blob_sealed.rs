//! Payload bytes sealed into a blob with a correct header and CRC (the
//! first byte's lowest bit picks int8 or f32, the rest a readable format
//! version), so mutations reach the decoder of every format's trailer and
//! the validation instead of stopping at the checksum.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcrnet_core::format::ModelKind;

fuzz_target!(|data: &[u8]| {
    let Some((&first, payload)) = data.split_first() else {
        return;
    };
    let kind = if first & 1 == 0 {
        ModelKind::Int8
    } else {
        ModelKind::F32
    };
    let blob = pcrnet_fuzz::seal(kind, pcrnet_fuzz::version_of(first >> 1), payload);
    pcrnet_fuzz::run_blob(
        &blob,
        &pcrnet_fuzz::fixed_cloud(),
        &pcrnet_fuzz::quick_options(),
    );
});
