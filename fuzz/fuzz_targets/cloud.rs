//! Arbitrary clouds (any f32 bit patterns, 0 to 300 points) and options
//! through the shipped int8 model: a typed error or a finite result.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcrnet_core::Int8Model;

fuzz_target!(|data: &[u8]| {
    let Some((options, points)) = data.split_first_chunk::<16>() else {
        return;
    };
    let Ok(model) = Int8Model::from_bytes(pcrnet_fuzz::SHIPPED) else {
        panic!("the shipped model loads");
    };
    let cloud = pcrnet_fuzz::cloud_from(points, 300);
    let mut scratch = vec![0i8; model.scratch_len(8)];
    if let Ok(r) = model.register(&cloud, &pcrnet_fuzz::options_from(options), &mut scratch) {
        pcrnet_fuzz::check(&r);
    }
});
