//! Helpers the reader tests share: points with exact coordinates, byte
//! builders for PCD headers and bodies (raw, struct-of-arrays, LZF), a
//! temporary file, a unit-square OFF mesh and error assertions.
//!
//! Each test file uses its own subset of these (every helper here is used
//! by at least two of them), hence the `dead_code` allowance.
#![allow(
    dead_code,
    reason = "each test file of tests/ compiles this module and uses only some of it"
)]

use std::path::PathBuf;

use pcrnet_io::FormatError;

/// Three points with distinct, exactly representable coordinates.
pub const PTS: [[f32; 3]; 3] = [[1.0, 2.0, 3.0], [-0.5, 0.25, 8.0], [1e-3, -7.75, 0.0]];

/// Little-endian f32 bytes of the points, x y z each.
pub fn le(points: &[[f32; 3]]) -> Vec<u8> {
    points
        .iter()
        .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
        .collect()
}

/// The parts, concatenated.
pub fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

/// A v0.7 PCD header of these fields, `w x h` points, stored as `data`.
pub fn pcd_header(
    fields: &str,
    size: &str,
    ty: &str,
    count: &str,
    w: usize,
    h: usize,
    data: &str,
) -> String {
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\n\
         TYPE {ty}\nCOUNT {count}\nWIDTH {w}\nHEIGHT {h}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {}\nDATA {data}\n",
        w * h
    )
}

/// A small greedy LZF compressor (brute-force match search) so the reader's
/// back-reference path is exercised by real-looking data.
pub fn lzf_compress(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut lit: Vec<u8> = Vec::new();
    let flush = |out: &mut Vec<u8>, lit: &mut Vec<u8>| {
        for chunk in lit.chunks(32) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        lit.clear();
    };
    let mut i = 0;
    while i < data.len() {
        let mut best = (0usize, 0usize); // (len, distance)
        for dist in 1..=i.min(8192) {
            let mut len = 0;
            while len < 264 && i + len < data.len() && data[i + len] == data[i + len - dist] {
                len += 1;
            }
            if len > best.0 {
                best = (len, dist);
            }
        }
        if best.0 >= 3 {
            flush(&mut out, &mut lit);
            let (len, dist) = best;
            let l = len - 2;
            let d = dist - 1;
            if l < 7 {
                out.push(((l << 5) | (d >> 8)) as u8);
            } else {
                out.push(((7 << 5) | (d >> 8)) as u8);
                out.push((l - 7) as u8);
            }
            out.push((d & 0xff) as u8);
            i += len;
        } else {
            lit.push(data[i]);
            i += 1;
        }
    }
    flush(&mut out, &mut lit);
    out
}

/// A `binary_compressed` PCD body: the compressed and uncompressed sizes,
/// then the LZF data.
pub fn compressed_body(soa: &[u8], lzf: &[u8]) -> Vec<u8> {
    cat(&[
        &(lzf.len() as u32).to_le_bytes(),
        &(soa.len() as u32).to_le_bytes(),
        lzf,
    ])
}

/// Struct-of-arrays layout of x, y, z f32 columns.
pub fn soa(points: &[[f32; 3]]) -> Vec<u8> {
    (0..3)
        .flat_map(|k| points.iter().flat_map(move |p| p[k].to_le_bytes()))
        .collect()
}

/// Writes `bytes` to `name` in this test run's temporary folder.
pub fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pcrnet-readers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// `r` is an error whose message contains every one of `words`.
pub fn assert_err_mentions<T: std::fmt::Debug>(r: Result<T, FormatError>, words: &[&str]) {
    let e = r.expect_err("expected an error");
    let msg = e.to_string();
    for w in words {
        assert!(msg.contains(w), "error {msg:?} does not mention {w:?}");
    }
}

/// Every proper prefix of `bytes` must fail to parse (and none may panic).
pub fn assert_every_truncation_fails<T: std::fmt::Debug>(
    bytes: &[u8],
    parse: impl Fn(&[u8]) -> Result<T, FormatError>,
) {
    parse(bytes).expect("the full file must parse");
    for cut in 0..bytes.len() {
        assert!(
            parse(&bytes[..cut]).is_err(),
            "prefix of {cut} of {} bytes parsed",
            bytes.len()
        );
    }
}

/// A unit square in z = 0 as an OFF quad.
pub const UNIT_SQUARE: &str =
    "OFF\n# unit square in z = 0\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
