//! OFF meshes: faces split into triangles, seeded sampling on the surface
//! weighted by area, the variants in the wild (ModelNet's glued counts,
//! COFF, NOFF, no keyword) and the errors.

mod common;

use common::{UNIT_SQUARE, assert_err_mentions};
use pcrnet_io::off;

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
