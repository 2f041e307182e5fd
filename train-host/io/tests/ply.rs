//! PLY files: ascii and binary (both byte orders), extra elements and
//! properties, integer coordinates, every truncation refused, garbage
//! headers, data errors and absurd counts.

mod common;

use common::{PTS, assert_err_mentions, assert_every_truncation_fails, cat, le};
use pcrnet_io::{FormatError, ply};

/// The size checks behind the point limit (`DEFAULT_MAX_POINTS` refuses
/// these counts first; `hostile_sizes.rs` tests that).
fn unlimited_ply(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    ply::parse_limited(bytes, usize::MAX)
}

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
