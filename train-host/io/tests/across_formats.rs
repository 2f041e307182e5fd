//! What holds for every format: reading a file by its extension
//! (`read_cloud`), I/O errors naming the file, non-finite points counted,
//! a UTF-8 byte order mark accepted, and the ModelNet data read when it
//! is present.

mod common;

use std::path::Path;

use common::{PTS, UNIT_SQUARE, cat, le, pcd_header, temp_file};
use pcrnet_io::{self, DEFAULT_OFF_SAMPLES, Format, ReadError, read_cloud, read_off_sampled};

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
