//! PCD files that do not parse, and what their errors say: truncated
//! binary data (also through `read_cloud`, naming the file), too few
//! points or values, garbage headers, absurd sizes (refused without
//! allocating) and corrupt LZF data.

mod common;

use common::{assert_err_mentions, cat, pcd_header, temp_file};
use pcrnet_io::{FormatError, ReadError, pcd, read_cloud};

/// The size checks behind the point limit (`DEFAULT_MAX_POINTS` refuses
/// these counts first; `hostile_sizes.rs` tests that).
fn unlimited_pcd(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    pcd::parse_limited(bytes, usize::MAX)
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
