//! Raw `.f32` clouds: little-endian IEEE-754 `f32` `x y z` triples, 12
//! bytes a point, one after the other, no header; the point count is the
//! length / 12. What firmware links with `include_bytes!` or `.incbin`
//! (`models/embedded-default-source.f32`). No frame, scale or count is
//! stored: the coordinates are in the cloud's own units.

use super::FormatError;

/// Bytes per point.
pub const POINT_BYTES: usize = 12;

/// The points of a raw `.f32` file, widened to `f64` as every reader's are;
/// a length that is not a multiple of [`POINT_BYTES`] is
/// [`FormatError::Truncated`], more than `max_points` points
/// [`FormatError::TooLarge`] (checked before allocating).
pub fn parse_f64_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f64; 3]>, FormatError> {
    let n = bytes.len() / POINT_BYTES;
    if !bytes.len().is_multiple_of(POINT_BYTES) {
        return Err(FormatError::Truncated {
            section: "raw f32 x y z triples".into(),
            expected: ((n + 1) * POINT_BYTES) as u64,
            unit: "bytes (a multiple of 12)",
            found: bytes.len() as u64,
        });
    }
    if n > max_points {
        return Err(FormatError::TooLarge {
            what: "raw f32 points",
            declared: n as u64,
            limit: max_points,
        });
    }
    Ok(bytes
        .chunks_exact(POINT_BYTES)
        .map(|p| {
            let c = |i: usize| f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]) as f64;
            [c(0), c(4), c(8)]
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triples_read_back_and_bad_lengths_are_errors() {
        let mut bytes = Vec::new();
        for v in [1.5f32, -2.0, 0.25, 3.0, 4.0, f32::MAX] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let points = parse_f64_limited(&bytes, 10).unwrap();
        assert_eq!(points, vec![[1.5, -2.0, 0.25], [3.0, 4.0, f32::MAX as f64]]);
        assert!(parse_f64_limited(&[], 10).unwrap().is_empty());
        let err = parse_f64_limited(&bytes[..13], 10).unwrap_err();
        assert!(err.to_string().contains("multiple of 12"), "{err}");
        assert!(matches!(
            parse_f64_limited(&bytes, 1),
            Err(FormatError::TooLarge { declared: 2, .. })
        ));
    }
}
