//! The OFF reader on arbitrary bytes: a typed error or finite points,
//! never a panic or an allocation the file cannot justify.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcrnet_io::Format;

fuzz_target!(|data: &[u8]| {
    if let Ok(points) = Format::Off.parse_limited(data, 1 << 20) {
        assert!(points.iter().flatten().all(|v| v.is_finite()));
    }
});
