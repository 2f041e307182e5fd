//! Point cloud readers: PCD, PLY, OFF and XYZ built from bytes in the tests.

use std::path::{Path, PathBuf};

use pcrnet_io::{
    self, DEFAULT_OFF_SAMPLES, Format, FormatError, ReadError, off, pcd, ply, read_cloud,
    read_off_sampled, xyz,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

// ---------------------------------------------------------------- helpers

/// Three points with distinct, exactly representable coordinates.
const PTS: [[f32; 3]; 3] = [[1.0, 2.0, 3.0], [-0.5, 0.25, 8.0], [1e-3, -7.75, 0.0]];

fn le(points: &[[f32; 3]]) -> Vec<u8> {
    points
        .iter()
        .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
        .collect()
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

fn pcd_header(
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

/// Literal-only LZF: control byte `len - 1` (< 32), then the bytes.
fn lzf_literal(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for chunk in data.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

/// A small greedy LZF compressor (brute-force match search) so the reader's
/// back-reference path is exercised by real-looking data.
fn lzf_compress(data: &[u8]) -> Vec<u8> {
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

fn compressed_body(soa: &[u8], lzf: &[u8]) -> Vec<u8> {
    cat(&[
        &(lzf.len() as u32).to_le_bytes(),
        &(soa.len() as u32).to_le_bytes(),
        lzf,
    ])
}

/// Struct-of-arrays layout of x, y, z f32 columns.
fn soa(points: &[[f32; 3]]) -> Vec<u8> {
    (0..3)
        .flat_map(|k| points.iter().flat_map(move |p| p[k].to_le_bytes()))
        .collect()
}

fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pcrnet-readers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn assert_err_mentions<T: std::fmt::Debug>(r: Result<T, FormatError>, words: &[&str]) {
    let e = r.expect_err("expected an error");
    let msg = e.to_string();
    for w in words {
        assert!(msg.contains(w), "error {msg:?} does not mention {w:?}");
    }
}

/// The size checks behind the point limit (`DEFAULT_MAX_POINTS` refuses
/// these counts first; `hostile_sizes.rs` tests that).
fn unlimited_pcd(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    pcd::parse_limited(bytes, usize::MAX)
}

fn unlimited_ply(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    ply::parse_limited(bytes, usize::MAX)
}

/// Every proper prefix of `bytes` must fail to parse (and none may panic).
fn assert_every_truncation_fails<T: std::fmt::Debug>(
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

// ---------------------------------------------------------------- PCD

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

/// `.csv` files read as XYZ text: a first line of column names is skipped,
/// a line that mixes names and numbers is still an error, and so are names
/// after the first point.
#[test]
fn csv_with_a_header() {
    assert_eq!(Format::from_path(Path::new("scan.CSV")), Some(Format::Csv));
    let csv = "x,y,z,intensity\n1,2,3,7\n-0.5,0.25,8,7\n";
    assert_eq!(Format::Csv.parse(csv.as_bytes()).unwrap(), &PTS[..2]);
    assert_eq!(
        Format::Xyz.parse(b"# scan\nX Y Z\n1 2 3\n").unwrap(),
        &PTS[..1]
    );
    for bad in ["1.0,abc,3\n1,2,3\n", "1,2,3\nx,y,z\n"] {
        let e = Format::Csv.parse(bad.as_bytes()).unwrap_err();
        assert!(e.to_string().contains("is not a number"), "{bad:?}: {e}");
    }
}

/// Every format drops a point with a non-finite coordinate and counts it
/// (`LocalCloud::left_out`), so a caller can say so.
#[test]
fn non_finite_points_are_counted() {
    let mut pcd = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 2, 2, "ascii");
    pcd += "1 2 3\nnan nan nan\n-0.5 0.25 8\n0 NaN 1\n";
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\ninf 0 0\n-0.5 0.25 8\n";
    let xyz = "nan 0 0\n1 2 3\n0 nan 1\n-0.5 0.25 8\n-inf 1 1\n";
    for (format, bytes, left_out) in [
        (Format::Pcd, pcd.as_str(), 2),
        (Format::Ply, ply, 1),
        (Format::Xyz, xyz, 3),
    ] {
        let cloud = format
            .parse_local(bytes.as_bytes(), 100, Some([0.0; 3]))
            .unwrap();
        assert_eq!(cloud.points, &PTS[..2], "{format:?}");
        assert_eq!(cloud.left_out, left_out, "{format:?}");
    }
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

#[test]
fn pcd_truncated_binary_message() {
    let h = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 1024, 1, "binary");
    let bytes = cat(&[h.as_bytes(), &[0u8; 100]]);
    assert_eq!(
        pcd::parse(&bytes).unwrap_err().to_string(),
        "DATA binary: expected 12288 bytes of points, found 100"
    );
    let path = temp_file("bunny.pcd", &bytes);
    let e = read_cloud(&path).unwrap_err();
    assert!(matches!(e, ReadError::Format { .. }));
    assert_eq!(
        e.to_string(),
        format!(
            "{}: DATA binary: expected 12288 bytes of points, found 100",
            path.display()
        )
    );
    assert!(e.to_string().contains("bunny.pcd: DATA binary"));
    std::fs::remove_file(path).unwrap();
}

#[test]
fn pcd_ascii_too_few_points_or_values() {
    let h = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, "ascii");
    assert_err_mentions(
        pcd::parse(format!("{h}1 2 3\n4 5 6\n").as_bytes()),
        &["DATA ascii", "expected 3 points, found 2"],
    );
    assert_err_mentions(
        pcd::parse(format!("{h}1 2 3\n4 5\n7 8 9\n").as_bytes()),
        &["line 13", "expected 3 values", "found 2"],
    );
    assert_err_mentions(
        pcd::parse(format!("{h}1 2 3\n4 five 6\n7 8 9\n").as_bytes()),
        &["line 13", "y value", "five", "not a number"],
    );
}

#[test]
fn pcd_garbage_headers() {
    let good_fields = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
    let cases: &[(&[u8], &[&str])] = &[
        (b"", &["empty"]),
        (b"\x00\xff\xfe garbage \x80\x81\n", &["not text"]),
        (b"hello world\n", &["unknown keyword", "HELLO"]),
        (b"VERSION 0.7\nFIELDS x y z\n", &["no DATA line"]),
        (
            b"FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n",
            &["FIELDS has no z"],
        ),
        (
            b"FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n",
            &["SIZE has 2 values"],
        ),
        (
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F Q\nWIDTH 1\nPOINTS 1\nDATA ascii\n",
            &["TYPE", "\"Q\""],
        ),
        (
            b"FIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n",
            &["field z", "not a supported number type"],
        ),
        (
            b"FIELDS x y z\nSIZE 4 4 4\nWIDTH 1\nPOINTS 1\nDATA ascii\n",
            &["no TYPE line"],
        ),
        (
            b"FIELDS x y z\nSIZE 4 4 four\nTYPE F F F\n",
            &["SIZE value", "four"],
        ),
    ];
    for (bytes, words) in cases {
        assert_err_mentions(pcd::parse(bytes), words);
    }
    let tail = |s: &str| format!("{good_fields}{s}");
    assert_err_mentions(
        pcd::parse(tail("WIDTH 4\nHEIGHT 2\nPOINTS 7\nDATA binary\n").as_bytes()),
        &["WIDTH 4 x HEIGHT 2", "POINTS 7"],
    );
    assert_err_mentions(
        pcd::parse(tail("WIDTH 1\nPOINTS 1\nDATA jpeg\n").as_bytes()),
        &["DATA", "jpeg"],
    );
    assert_err_mentions(
        pcd::parse(tail("POINTS 1\nDATA\n").as_bytes()),
        &["DATA line names no storage kind"],
    );
    assert_err_mentions(pcd::parse(tail("DATA binary\n").as_bytes()), &["POINTS"]);
}

#[test]
fn pcd_absurd_sizes_error_without_allocating() {
    // A huge POINTS must fail on the size check, not try to allocate.
    let h = format!(
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS {}\nDATA binary\n",
        usize::MAX / 2
    );
    assert_err_mentions(unlimited_pcd(h.as_bytes()), &["DATA binary", "overflows"]);
    let h = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1000000000000\nDATA binary\n";
    assert_err_mentions(
        unlimited_pcd(cat(&[h.as_bytes(), &[0; 64]]).as_slice()),
        &["expected 12000000000000 bytes of points, found 64"],
    );
    let h = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1000000000000\nDATA ascii\n1 2 3\n";
    assert_err_mentions(
        unlimited_pcd(h.as_bytes()),
        &["expected 1000000000000 points, found 1"],
    );
    // Compressed: sizes in the block header that lie.
    let h = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA binary_compressed\n";
    let body = cat(&[&u32::MAX.to_le_bytes(), &12u32.to_le_bytes(), &[0x0b; 13]]);
    assert_err_mentions(
        unlimited_pcd(&cat(&[h.as_bytes(), &body])),
        &["expected 4294967295 bytes of compressed data, found 13"],
    );
    let body = cat(&[&13u32.to_le_bytes(), &u32::MAX.to_le_bytes(), &[0x0b; 13]]);
    assert_err_mentions(
        unlimited_pcd(&cat(&[h.as_bytes(), &body])),
        &["uncompressed size 4294967295", "12"],
    );
    let h = format!(
        "FIELDS x y z pad\nSIZE 4 4 4 {}\nTYPE F F F U\nCOUNT 1 1 1 2\nPOINTS 1\nDATA binary\n",
        usize::MAX
    );
    assert_err_mentions(unlimited_pcd(h.as_bytes()), &["field pad", "overflows"]);
}

#[test]
fn pcd_corrupt_lzf() {
    let h = pcd_header(
        "x y z",
        "4 4 4",
        "F F F",
        "1 1 1",
        1,
        1,
        "binary_compressed",
    );
    let cases: &[(&[u8], &str)] = &[
        // Back-reference before the start of the output.
        (&[0x40, 0x05, 0x0b], "back-reference"),
        // Literal run longer than the data.
        (&[0x1f, 1, 2, 3], "ends early"),
        // Decompresses to fewer bytes than declared.
        (&[0x02, 1, 2, 3], "decompresses to 3 bytes, expected 12"),
        // Decompresses past the declared size.
        (
            &[0x0b, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xE0, 0xff, 0x00],
            "past 12 bytes",
        ),
    ];
    for (lzf, word) in cases {
        let body = cat(&[&(lzf.len() as u32).to_le_bytes(), &12u32.to_le_bytes(), lzf]);
        assert_err_mentions(
            pcd::parse(&cat(&[h.as_bytes(), &body])),
            &["binary_compressed", word],
        );
    }
}

// ---------------------------------------------------------------- PLY

#[test]
fn ply_ascii_with_faces_and_extra_properties() {
    let f = "ply\nformat ascii 1.0\ncomment made by hand\nobj_info x\n\
             element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty float nx\n\
             element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\n\
             end_header\n\
             1 2 3 255 0.5\n-0.5 0.25 8 0 1\n0.001 -7.75 0 7 1e-3\n\
             3 0 1 2 9\n4 0 1 2 0 9\n";
    assert_eq!(ply::parse(f.as_bytes()).unwrap(), PTS);
    // A face list cut short is an error, not silently accepted.
    let cut = f.trim_end().trim_end_matches("4 0 1 2 0 9");
    assert_err_mentions(
        ply::parse(cut.as_bytes()),
        &["face", "expected 2 rows, found 1"],
    );
}

#[test]
fn ply_binary_little_endian() {
    let h = "ply\r\nformat binary_little_endian 1.0\r\nelement vertex 3\r\n\
             property float32 x\r\nproperty float32 y\r\nproperty float32 z\r\n\
             property uint8 alpha\r\nelement face 1\r\n\
             property list uint8 uint32 vertex_indices\r\nend_header\r\n";
    let mut body = Vec::new();
    for p in PTS {
        body.extend(le(&[p]));
        body.push(0xff);
    }
    body.push(3);
    for i in [0u32, 1, 2] {
        body.extend(i.to_le_bytes());
    }
    let bytes = cat(&[h.as_bytes(), &body]);
    assert_eq!(ply::parse(&bytes).unwrap(), PTS);
    assert_every_truncation_fails(&bytes, ply::parse);
}

#[test]
fn ply_binary_big_endian_double_with_elements_before_vertex() {
    // A list-bearing element and a scalar-only element precede the vertices.
    let h = "ply\nformat binary_big_endian 1.0\n\
             element tags 2\nproperty list ushort short ids\nproperty char c\n\
             element material 2\nproperty double shininess\nproperty int id\n\
             element vertex 3\nproperty short label\nproperty double x\nproperty float64 y\n\
             property double z\nproperty list uchar float extra\n\
             element face 1\nproperty list int int vertex_indices\nend_header\n";
    let mut body: Vec<u8> = Vec::new();
    // tags: [2 ids, c], [0 ids, c]
    body.extend(2u16.to_be_bytes());
    body.extend(5i16.to_be_bytes());
    body.extend((-6i16).to_be_bytes());
    body.push(1);
    body.extend(0u16.to_be_bytes());
    body.push(2);
    // material
    for _ in 0..2 {
        body.extend(0.5f64.to_be_bytes());
        body.extend(3i32.to_be_bytes());
    }
    for (i, p) in PTS.iter().enumerate() {
        body.extend((i as i16).to_be_bytes());
        for v in p {
            body.extend(f64::from(*v).to_be_bytes());
        }
        body.push(i as u8);
        for _ in 0..i {
            body.extend(1.5f32.to_be_bytes());
        }
    }
    body.extend(3i32.to_be_bytes());
    for i in [0i32, 1, 2] {
        body.extend(i.to_be_bytes());
    }
    let bytes = cat(&[h.as_bytes(), &body]);
    assert_eq!(ply::parse(&bytes).unwrap(), PTS);
    assert_every_truncation_fails(&bytes, ply::parse);
}

#[test]
fn ply_integer_coordinates_and_non_finite_vertices() {
    let h = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n\
             property int x\nproperty ushort y\nproperty float z\nend_header\n";
    let mut body = Vec::new();
    for (x, y, z) in [(-4i32, 5u16, 0.5f32), (1, 2, f32::NAN), (7, 65535, -1.0)] {
        body.extend(x.to_le_bytes());
        body.extend(y.to_le_bytes());
        body.extend(z.to_le_bytes());
    }
    assert_eq!(
        ply::parse(&cat(&[h.as_bytes(), &body])).unwrap(),
        [[-4.0, 5.0, 0.5], [7.0, 65535.0, -1.0]]
    );
}

#[test]
fn ply_garbage_headers() {
    let cases: &[(&str, &[&str])] = &[
        ("", &["empty"]),
        ("PLY but not really\n", &["not \"ply\""]),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
            &["no end_header"],
        ),
        (
            "ply\nformat ebcdic 1.0\nend_header\n",
            &["unknown format", "ebcdic"],
        ),
        (
            "ply\nelement vertex 1\nproperty float x\nend_header\n",
            &["no format line"],
        ),
        (
            "ply\nformat ascii 1.0\nelement face 1\nend_header\n",
            &["no vertex element"],
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n",
            &["no z property"],
        ),
        (
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
            &["property before any element"],
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex many\nend_header\n",
            &["count", "many", "not a number"],
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty quaternion x\nend_header\n",
            &["unknown type", "quaternion"],
        ),
        (
            "ply\nformat ascii 1.0\nelement f 1\nproperty list float int idx\nend_header\n",
            &["count type", "not an integer"],
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\n\
             property float y\nproperty float z\nend_header\n",
            &["x is a list"],
        ),
        (
            "ply\nformat ascii 1.0\nwhat is this\nend_header\n",
            &["line 3", "what is this"],
        ),
    ];
    for (text, words) in cases {
        assert_err_mentions(ply::parse(text.as_bytes()), words);
    }
}

#[test]
fn ply_data_errors_and_absurd_counts() {
    let h = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
             property float z\nend_header\n";
    assert_err_mentions(
        unlimited_ply(format!("{h}1 2 3\n4 x 6\n").as_bytes()),
        &["vertex", "row 1", "y value", "\"x\""],
    );
    assert_err_mentions(
        unlimited_ply(format!("{h}1 2 3\n").as_bytes()),
        &["expected 2 rows, found 1"],
    );
    let h = "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000\n\
             property float x\nproperty float y\nproperty float z\nend_header\n";
    assert_err_mentions(
        unlimited_ply(cat(&[h.as_bytes(), &[0; 24]]).as_slice()),
        &[
            "element \"vertex\"",
            "expected 12000000000000000 bytes, found 24",
        ],
    );
    let h = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\n\
         property double y\nproperty double z\nend_header\n",
        usize::MAX
    );
    assert!(unlimited_ply(h.as_bytes()).is_err());
    // A list claiming 2^32 - 1 items, in binary and ascii.
    let h = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
             property float y\nproperty float z\nproperty list uint uchar junk\nend_header\n";
    let body = cat(&[&le(&[PTS[0]]), &u32::MAX.to_le_bytes(), &[1, 2, 3]]);
    assert_err_mentions(
        unlimited_ply(&cat(&[h.as_bytes(), &body])),
        &["expected 1 rows, found 0"],
    );
    let h = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
             property float z\nproperty list uint uchar junk\nend_header\n";
    assert_err_mentions(
        unlimited_ply(format!("{h}1 2 3 4294967295 1 2 3\n").as_bytes()),
        &["expected 1 rows, found 0"],
    );
    // Negative list length in a signed count type.
    let h = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
             property float y\nproperty float z\nproperty list char uchar junk\nend_header\n";
    let body = cat(&[&le(&[PTS[0]]), &[0xff]]);
    assert_err_mentions(
        unlimited_ply(&cat(&[h.as_bytes(), &body])),
        &["negative length"],
    );
}

// ---------------------------------------------------------------- OFF

const UNIT_SQUARE: &str =
    "OFF\n# unit square in z = 0\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

#[test]
fn off_quad_fan_and_mesh() {
    let m = off::parse(UNIT_SQUARE.as_bytes()).unwrap();
    assert_eq!(
        m.vertices,
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0]
        ]
    );
    assert_eq!(m.triangles, [[0, 1, 2], [0, 2, 3]]);
}

#[test]
fn off_sampling_on_surface_and_deterministic() {
    let n = 1000;
    let a = off::parse_sampled(UNIT_SQUARE.as_bytes(), n, 42).unwrap();
    assert_eq!(a.len(), n);
    for p in &a {
        assert_eq!(p[2], 0.0);
        assert!(
            (0.0..=1.0).contains(&p[0]) && (0.0..=1.0).contains(&p[1]),
            "{p:?}"
        );
    }
    assert_eq!(
        a,
        off::parse_sampled(UNIT_SQUARE.as_bytes(), n, 42).unwrap()
    );
    assert_ne!(
        a,
        off::parse_sampled(UNIT_SQUARE.as_bytes(), n, 43).unwrap()
    );
    // Uniform over the square: each half (split by the diagonal) gets ~half,
    // and each quadrant ~a quarter.
    let below = a.iter().filter(|p| p[1] < p[0]).count() as f64 / n as f64;
    assert!((below - 0.5).abs() < 0.06, "{below}");
    let q = a.iter().filter(|p| p[0] < 0.5 && p[1] < 0.5).count() as f64 / n as f64;
    assert!((q - 0.25).abs() < 0.05, "{q}");
    assert!(
        off::parse_sampled(UNIT_SQUARE.as_bytes(), 0, 1)
            .unwrap()
            .is_empty()
    );
}

#[test]
fn off_sampling_weights_by_area() {
    // Triangle A (area 0.5) in z = 0 and triangle B (area 1.5) in z = 5.
    let f = "OFF\n6 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 5\n3 0 5\n0 1 5\n3 0 1 2\n3 3 4 5\n";
    let pts = off::parse_sampled(f.as_bytes(), 4000, 9).unwrap();
    let on_b = pts.iter().filter(|p| p[2] == 5.0).count();
    assert_eq!(pts.iter().filter(|p| p[2] == 0.0).count() + on_b, 4000);
    let frac = on_b as f64 / 4000.0;
    assert!((frac - 0.75).abs() < 0.03, "{frac}");
    // Inside triangle B: x/3 + y <= 1.
    for p in pts.iter().filter(|p| p[2] == 5.0) {
        assert!(
            p[0] >= 0.0 && p[1] >= 0.0 && p[0] / 3.0 + p[1] <= 1.0 + 1e-6,
            "{p:?}"
        );
    }
}

#[test]
fn off_variants() {
    // ModelNet quirk: counts glued to the keyword.
    let glued = "OFF4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
    let m = off::parse(glued.as_bytes()).unwrap();
    assert_eq!((m.vertices.len(), m.triangles.len()), (4, 2));
    // Counts on the keyword line, COFF colours, CRLF, a degenerate edge face.
    let coff = "COFF 3 2 0\r\n0 0 0 255 0 0 255\r\n2 0 0 0 255 0 255\r\n0 2 0 0 0 255 255\r\n\
                3 0 1 2 128 128 128\r\n2 0 1\r\n";
    let m = off::parse(coff.as_bytes()).unwrap();
    assert_eq!(m.vertices[1], [2.0, 0.0, 0.0]);
    assert_eq!(m.triangles, [[0, 1, 2]]);
    // NOFF with normals; no edge count; no keyword at all.
    let noff = "NOFF\n3 1\n0 0 1 0 0 1\n1 0 1 0 0 1\n0 1 1 0 0 1\n3 0 1 2\n";
    let pts = off::parse_sampled(noff.as_bytes(), 50, 0).unwrap();
    assert!(pts.iter().all(|p| p[2] == 1.0));
    let bare = "3 1 0\n0 0 1\n1 0 1\n0 1 1\n3 0 1 2\n";
    assert_eq!(
        off::parse(bare.as_bytes()).unwrap(),
        off::parse(noff.as_bytes()).unwrap()
    );
}

#[test]
fn off_errors() {
    let cases: &[(&str, &[&str])] = &[
        ("", &["empty"]),
        (
            "solid cube\nfacet normal 0 0 1\n",
            &["neither OFF", "solid cube"],
        ),
        ("4OFF\n1 0 0\n0 0 0 0\n", &["unsupported variant", "4OFF"]),
        ("OFF BINARY\n", &["binary OFF"]),
        ("OFF\n", &["no vertex/face count line"]),
        ("OFF\n3\n", &["no face count"]),
        ("OFF\nthree 1 0\n", &["vertex count", "three"]),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n",
            &["OFF vertices", "expected 3 vertices, found 2"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1\n3 0 1 2\n",
            &["line 5", "vertex 2", "3 coordinates"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 nan\n3 0 1 2\n",
            &["vertex 2", "non-finite"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 zed\n3 0 1 2\n",
            &["z value", "zed"],
        ),
        (
            "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
            &["OFF faces", "expected 2 faces, found 1"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
            &["face 0", "index 3 out of range"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n",
            &["expected 4 vertex indices, found 3"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n",
            &["vertex index", "-1"],
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n99999999999999999999 0 1 2\n",
            &["vertex count"],
        ),
    ];
    for (text, words) in cases {
        assert_err_mentions(off::parse_sampled(text.as_bytes(), 10, 0), words);
    }
    // No faces, or only point and edge faces: the vertices are the cloud
    // (a common way to store a scan); zero area is still an error.
    let tri = vec![[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert_eq!(
        off::parse_sampled(b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", 10, 0).unwrap(),
        tri
    );
    assert_eq!(
        off::parse_sampled(b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", 10, 0).unwrap(),
        tri
    );
    assert_err_mentions(
        off::parse_sampled(b"OFF\n3 1 0\n0 0 0\n1 1 1\n2 2 2\n3 0 1 2\n", 10, 0),
        &["total surface area is 0"],
    );
    // A hand-built mesh with a bad index errors instead of panicking.
    let m = off::Mesh {
        vertices: vec![[0.0; 3]],
        triangles: vec![[0, 0, 5]],
    };
    assert_err_mentions(off::sample(&m, 3, 0), &["index 5 out of range"]);
}

// ---------------------------------------------------------------- XYZ

#[test]
fn xyz_separators_comments_and_extra_columns() {
    let f = "# x y z nx ny nz\n1 2 3\n\n  -0.5,0.25,8,0,0,1\n0.001\t-7.75 ,0 label # trailing\n\
             nan 1 1\n";
    assert_eq!(xyz::parse(f.as_bytes()).unwrap(), PTS);
    assert!(xyz::parse(b"").unwrap().is_empty());
}

#[test]
fn xyz_errors() {
    assert_err_mentions(
        xyz::parse(b"1 2 3\n4 5\n"),
        &["XYZ line 2", "expected 3 numbers, found 2"],
    );
    assert_err_mentions(
        xyz::parse(b"1 2 3\n\n4 5 six\n"),
        &["XYZ line 3", "z value", "six"],
    );
    // A first line of names alone is a header (`csv_with_a_header`); one
    // that mixes names and numbers is not.
    assert_err_mentions(xyz::parse(b"x,2,z\n1,2,3\n"), &["XYZ line 1", "x value"]);
    assert_err_mentions(xyz::parse(b"1 2 3\n\xff\xfe\n"), &["not text"]);
}

// ---------------------------------------------------------------- files

#[test]
fn read_cloud_dispatches_by_extension() {
    let h = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, "binary");
    let pcd_bytes = cat(&[h.as_bytes(), &le(&PTS)]);
    let files = [
        temp_file("a.pcd", &pcd_bytes),
        temp_file("b.PCD", &pcd_bytes),
        temp_file("c.xyz", b"1 2 3\n-0.5 0.25 8\n0.001 -7.75 0\n"),
        temp_file("d.Txt", b"1,2,3\n-0.5,0.25,8\n0.001,-7.75,0\n"),
        temp_file(
            "e.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
              property float z\nend_header\n1 2 3\n-0.5 0.25 8\n0.001 -7.75 0\n",
        ),
    ];
    for f in &files {
        assert_eq!(read_cloud(f).unwrap(), PTS, "{}", f.display());
    }
    let off_file = temp_file("square.OFF", UNIT_SQUARE.as_bytes());
    let sampled = read_cloud(&off_file).unwrap();
    assert_eq!(sampled.len(), DEFAULT_OFF_SAMPLES);
    assert_eq!(sampled, read_cloud(&off_file).unwrap());
    assert_eq!(
        sampled,
        read_off_sampled(&off_file, DEFAULT_OFF_SAMPLES, pcrnet_io::DEFAULT_OFF_SEED).unwrap()
    );
    assert_eq!(read_off_sampled(&off_file, 10, 3).unwrap().len(), 10);
    assert_eq!(Format::from_path(Path::new("x/y.Ply")), Some(Format::Ply));
    assert_eq!(Format::from_path(Path::new("noext")), None);

    let unknown = temp_file("cloud.las", b"whatever");
    let e = read_cloud(&unknown).unwrap_err();
    assert!(matches!(e, ReadError::UnknownFormat { .. }));
    assert!(
        e.to_string()
            .contains("cloud.las: unknown point cloud format"),
        "{e}"
    );

    let bad = temp_file("broken.off", b"OFF\n3 1 0\n0 0 0\n");
    let e = read_cloud(&bad).unwrap_err();
    assert!(
        e.to_string()
            .contains("broken.off: OFF vertices: expected 3 vertices, found 1"),
        "{e}"
    );

    for f in files.iter().chain([&off_file, &unknown, &bad]) {
        std::fs::remove_file(f).unwrap();
    }
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let path = Path::new("/definitely/not/here/bunny.pcd");
    let e = read_cloud(path).unwrap_err();
    assert!(matches!(e, ReadError::Io { .. }));
    assert!(
        e.to_string()
            .starts_with("/definitely/not/here/bunny.pcd: "),
        "{e}"
    );
    assert!(
        read_off_sampled(Path::new("/nope/mesh.off"), 5, 0)
            .unwrap_err()
            .to_string()
            .contains("mesh.off")
    );
}

// ---------------------------------------------------------------- robustness

#[test]
fn mutated_files_never_panic() {
    let h = pcd_header("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", 3, 1, "binary");
    let pcd_bin = cat(&[h.as_bytes(), &[7u8; 48]]);
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
    let pcd_comp = cat(&[h.as_bytes(), &compressed_body(&data, &lzf_compress(&data))]);
    let ply_bin = {
        let h = "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n\
                 property float y\nproperty float z\nelement face 1\n\
                 property list uchar int vertex_indices\nend_header\n";
        cat(&[h.as_bytes(), &[0u8; 24], &[3], &[0u8; 12]])
    };
    let samples: Vec<(Vec<u8>, Format)> = vec![
        (pcd_bin, Format::Pcd),
        (pcd_comp, Format::Pcd),
        (ply_bin, Format::Ply),
        (UNIT_SQUARE.as_bytes().to_vec(), Format::Off),
        (b"1 2 3\n4,5,6\n".to_vec(), Format::Xyz),
        (b"x,y,z\n1,2,3\n4,5,6\n".to_vec(), Format::Csv),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let interesting = [b'0', b'9', b'\n', b' ', 0, 0xff, b'-', b'#', 0x80];
    // READERS_FUZZ_ITERS raises the count for a longer local run.
    let iters: usize = std::env::var("READERS_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1500);
    for (orig, format) in &samples {
        for _ in 0..iters {
            let mut b = orig.clone();
            for _ in 0..rng.random_range(1..4) {
                let i = rng.random_range(0..b.len());
                match rng.random_range(0..4) {
                    0 => b[i] = rng.random(),
                    1 => b[i] = interesting[rng.random_range(0..interesting.len())],
                    2 => {
                        b.remove(i);
                    }
                    _ => b.insert(i, rng.random()),
                }
                if b.is_empty() {
                    break;
                }
            }
            // Only the absence of panics matters here.
            let _ = format.parse(&b);
        }
    }
}

// ---------------------------------------------------------------- real data

#[test]
fn reads_modelnet_chair_if_present() {
    let dir = Path::new("/work/shared/data/ModelNet10/chair/train");
    if !dir.is_dir() {
        println!("skipping: {} not found", dir.display());
        return;
    }
    let Some(file) = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| Format::from_path(p) == Some(Format::Pcd))
        .min()
    else {
        println!("skipping: no .pcd file in {}", dir.display());
        return;
    };
    let pts = read_cloud(&file).unwrap();
    assert_eq!(pts.len(), 1024, "{}", file.display());
    assert!(pts.iter().flatten().all(|v| v.is_finite() && v.abs() < 1e4));
    // Not all identical: a real shape.
    assert!(pts.iter().any(|p| p != &pts[0]));
}

#[test]
fn a_utf8_byte_order_mark_is_accepted_in_every_format() {
    let bom = b"\xEF\xBB\xBF";
    let points = vec![[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]];
    let files: [(&str, &[u8]); 4] = [
        ("bom.xyz", b"1 2 3\n4 5 6\n"),
        (
            "bom.pcd",
            b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n",
        ),
        (
            "bom.ply",
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n",
        ),
        ("bom.off", b"OFF\n2 0 0\n1 2 3\n4 5 6\n"),
    ];
    for (name, body) in files {
        let path = temp_file(name, &cat(&[bom, body]));
        let read = pcrnet_io::read_cloud(&path);
        assert_eq!(
            read.unwrap_or_else(|e| panic!("{name}: {e}")),
            points,
            "{name}"
        );
        let _ = std::fs::remove_file(path);
    }
}
