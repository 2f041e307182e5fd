//! Raw blob bytes through the int8 and f32 loaders; whatever loads runs
//! every entry point on a fixed cloud.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    pcrnet_fuzz::run_blob(
        data,
        &pcrnet_fuzz::fixed_cloud(),
        &pcrnet_fuzz::quick_options(),
    );
});
