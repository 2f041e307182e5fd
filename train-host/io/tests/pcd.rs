//! PCD files that parse: ascii, binary and binary_compressed storage,
//! every field type and layout, organised clouds with NaN holes, the v0.6
//! header, and every truncation of a good file refused.

mod common;

use common::{
    PTS, assert_every_truncation_fails, cat, compressed_body, le, lzf_compress, pcd_header, soa,
};
use pcrnet_io::pcd;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Literal-only LZF: control byte `len - 1` (< 32), then the bytes.
fn lzf_literal(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for chunk in data.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

#[test]
fn pcd_ascii() {
    let mut f = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, "ascii");
    f += "1 2 3\n-0.5 0.25 8\r\n\n0.001 -7.75 0\n";
    assert_eq!(pcd::parse(f.as_bytes()).unwrap(), PTS);
}

#[test]
fn pcd_ascii_extra_fields_and_counts() {
    // Fields before, between and after x/y/z, one with COUNT 3.
    let mut f = pcd_header(
        "intensity x y hist z rgb",
        "4 4 4 4 4 4",
        "F F F F F U",
        "1 1 1 3 1 1",
        2,
        1,
        "ascii",
    );
    f += "9 1 2 7 7 7 3 4278190080\n9 -0.5 0.25 7 7 7 8 255\n";
    assert_eq!(pcd::parse(f.as_bytes()).unwrap(), &PTS[..2]);
}

#[test]
fn pcd_ascii_organised_nan_rows_dropped() {
    let mut f = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 2, 2, "ascii");
    f += "1 2 3\nnan nan nan\n-0.5 0.25 8\n0 NaN 1\n";
    assert_eq!(pcd::parse(f.as_bytes()).unwrap(), &PTS[..2]);
}

#[test]
fn pcd_v06_header_without_version_or_count() {
    let f = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA binary\n";
    let bytes = cat(&[f.as_bytes(), &le(&PTS)]);
    assert_eq!(pcd::parse(&bytes).unwrap(), PTS);
}

#[test]
fn pcd_binary() {
    let h = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, "binary");
    let bytes = cat(&[h.as_bytes(), &le(&PTS)]);
    assert_eq!(pcd::parse(&bytes).unwrap(), PTS);
    // Trailing bytes after the declared points are ignored.
    let longer = cat(&[&bytes, b"junk"]);
    assert_eq!(pcd::parse(&longer).unwrap(), PTS);
}

#[test]
fn pcd_binary_mixed_types_and_extra_fields() {
    // x f64, y i16, z u8, with rgb (U 4), padding `_` (2 bytes), normals
    // (F 4 x 3, COUNT 1 each) and a COUNT 2 descriptor around them.
    let h = pcd_header(
        "rgb x _ y normal_x normal_y normal_z desc z curvature",
        "4 8 2 2 4 4 4 4 1 4",
        "U F U I F F F F U F",
        "1 1 1 1 1 1 1 2 1 1",
        2,
        1,
        "binary",
    );
    let rec = |x: f64, y: i16, z: u8| -> Vec<u8> {
        cat(&[
            &0xff00_ff00u32.to_le_bytes(),
            &x.to_le_bytes(),
            &[0xAA, 0xBB],
            &y.to_le_bytes(),
            &1f32.to_le_bytes(),
            &2f32.to_le_bytes(),
            &3f32.to_le_bytes(),
            &9f32.to_le_bytes(),
            &9f32.to_le_bytes(),
            &[z],
            &0.5f32.to_le_bytes(),
        ])
    };
    let bytes = cat(&[h.as_bytes(), &rec(1.5, -300, 200), &rec(-2.25, 7, 0)]);
    assert_eq!(
        pcd::parse(&bytes).unwrap(),
        [[1.5, -300.0, 200.0], [-2.25, 7.0, 0.0]]
    );
}

#[test]
fn pcd_binary_rgb_as_float_and_integer_xyz() {
    let h = pcd_header("x y z rgb", "4 4 4 4", "I I U F", "1 1 1 1", 1, 1, "binary");
    let bytes = cat(&[
        h.as_bytes(),
        &(-5i32).to_le_bytes(),
        &7i32.to_le_bytes(),
        &9u32.to_le_bytes(),
        &f32::from_bits(0x00ff_0000).to_le_bytes(),
    ]);
    assert_eq!(pcd::parse(&bytes).unwrap(), [[-5.0, 7.0, 9.0]]);
}

#[test]
fn pcd_binary_organised_nan_dropped() {
    let nan = f32::NAN;
    let grid = [
        PTS[0],
        [nan, nan, nan],
        PTS[1],
        [nan, 1.0, 1.0],
        [1.0, 1.0, f32::INFINITY],
        PTS[2],
    ];
    let h = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, 2, "binary");
    let bytes = cat(&[h.as_bytes(), &le(&grid)]);
    assert_eq!(pcd::parse(&bytes).unwrap(), PTS);
}

#[test]
fn pcd_binary_compressed_literal_only() {
    let h = pcd_header(
        "x y z",
        "4 4 4",
        "F F F",
        "1 1 1",
        3,
        1,
        "binary_compressed",
    );
    let data = soa(&PTS);
    let bytes = cat(&[h.as_bytes(), &compressed_body(&data, &lzf_literal(&data))]);
    assert_eq!(pcd::parse(&bytes).unwrap(), PTS);
}

#[test]
fn pcd_binary_compressed_back_references() {
    // Four points (1, 1, 1): each column is one literal float plus an
    // overlapping back-reference of 12 bytes at distance 4 (long form),
    // or of 4 + 4 bytes (short form).
    let one = 1f32.to_le_bytes();
    let mut lzf = Vec::new();
    // x: literal 4 bytes, then long back-reference (len 12 = 7 + 3 + 2).
    lzf.extend([0x03, one[0], one[1], one[2], one[3], 0xE0, 0x03, 0x03]);
    // y and z: two short back-references of 4 bytes each (len field 2).
    for _ in 0..2 {
        lzf.extend([
            0x03, one[0], one[1], one[2], one[3], 0x40, 0x03, 0x40, 0x03, 0x40, 0x03,
        ]);
    }
    let h = pcd_header(
        "x y z",
        "4 4 4",
        "F F F",
        "1 1 1",
        4,
        1,
        "binary_compressed",
    );
    let bytes = cat(&[h.as_bytes(), &compressed_body(&[0; 48], &lzf)]);
    assert_eq!(pcd::parse(&bytes).unwrap(), [[1.0f32; 3]; 4]);
}

#[test]
fn pcd_binary_compressed_matches_binary_with_extra_fields() {
    // 200 points on a coarse grid (so the data repeats and compresses),
    // with rgb and a COUNT 2 field, organised 20 x 10 with NaN holes.
    let n = 200;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let pts: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            if i % 17 == 3 {
                [f32::NAN; 3]
            } else {
                [
                    (rng.random_range(0..4) as f32) * 0.5,
                    (i / 20) as f32,
                    rng.random_range(-2..2) as f32,
                ]
            }
        })
        .collect();
    let rgb: Vec<u32> = (0..n).map(|i| (i as u32 % 3) * 0x10101).collect();
    let fields = ("x rgb y pair z", "4 4 4 4 4", "F U F F F", "1 1 1 2 1");
    // Binary (array of structs).
    let mut aos = Vec::new();
    for (p, c) in pts.iter().zip(&rgb) {
        aos.extend(p[0].to_le_bytes());
        aos.extend(c.to_le_bytes());
        aos.extend(p[1].to_le_bytes());
        aos.extend([0u8; 8]);
        aos.extend(p[2].to_le_bytes());
    }
    // Compressed (struct of arrays: each field's column in turn).
    let mut cols = Vec::new();
    cols.extend(pts.iter().flat_map(|p| p[0].to_le_bytes()));
    cols.extend(rgb.iter().flat_map(|c| c.to_le_bytes()));
    cols.extend(pts.iter().flat_map(|p| p[1].to_le_bytes()));
    cols.extend(std::iter::repeat_n(0u8, 8 * n));
    cols.extend(pts.iter().flat_map(|p| p[2].to_le_bytes()));
    let lzf = lzf_compress(&cols);
    assert!(
        lzf.len() < cols.len() / 2,
        "test compressor should compress"
    );

    let hb = pcd_header(fields.0, fields.1, fields.2, fields.3, 20, 10, "binary");
    let hc = pcd_header(
        fields.0,
        fields.1,
        fields.2,
        fields.3,
        20,
        10,
        "binary_compressed",
    );
    let from_binary = pcd::parse(&cat(&[hb.as_bytes(), &aos])).unwrap();
    let compressed = cat(&[hc.as_bytes(), &compressed_body(&cols, &lzf)]);
    let from_compressed = pcd::parse(&compressed).unwrap();
    let expected: Vec<[f32; 3]> = pts.iter().copied().filter(|p| !p[0].is_nan()).collect();
    assert_eq!(from_binary, expected);
    assert_eq!(from_compressed, expected);
    assert_every_truncation_fails(&compressed, pcd::parse);
}

#[test]
fn pcd_every_truncation_of_binary_fails() {
    let h = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, "binary");
    assert_every_truncation_fails(&cat(&[h.as_bytes(), &le(&PTS)]), pcd::parse);
    let h = pcd_header(
        "x y z",
        "4 4 4",
        "F F F",
        "1 1 1",
        3,
        1,
        "binary_compressed",
    );
    let data = soa(&PTS);
    let bytes = cat(&[h.as_bytes(), &compressed_body(&data, &lzf_literal(&data))]);
    assert_every_truncation_fails(&bytes, pcd::parse);
}
