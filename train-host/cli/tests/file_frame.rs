//! Issue 10, items 1 and 14: clouds at map coordinates register as well as
//! the same clouds at the origin, the pose comes back in the files' frame,
//! and `--aligned` writes the format its extension names, exactly.

use std::path::{Path, PathBuf};
use std::process::Command;

use pcrnet_io::write::encode;
use pcrnet_io::{Format, off, pcd, ply, xyz};
use pcrnet_train::shapes::{Shape, sample};

/// A UTM-like offset: easting 500 km, northing 5,400 km, 120 m up.
const UTM: [f64; 3] = [500_000.0, 5_400_000.0, 120.0];
/// The source is the template moved by 0.1 m along x.
const SHIFT: [f64; 3] = [0.1, 0.0, 0.0];

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pcrnet-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The template (a 1-unit generated shape) and the source, both moved by
/// `offset`, written as XYZ text at full f64 precision.
fn write_pair(d: &Path, offset: [f64; 3]) -> (PathBuf, PathBuf, Vec<[f64; 3]>) {
    let shape: Vec<[f64; 3]> = sample(Shape::Ell, 512, 3)
        .iter()
        .map(|p| [0, 1, 2].map(|k| f64::from(p[k]) + offset[k]))
        .collect();
    let source: Vec<[f64; 3]> = shape
        .iter()
        .map(|p| [0, 1, 2].map(|k| p[k] + SHIFT[k]))
        .collect();
    let (t, s) = (d.join("template.xyz"), d.join("source.xyz"));
    std::fs::write(&t, encode(Format::Xyz, &shape)).unwrap();
    std::fs::write(&s, encode(Format::Xyz, &source)).unwrap();
    (t, s, shape)
}

fn register_icp(t: &Path, s: &Path, extra: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_pcrnet"))
        .args(["register".as_ref(), t.as_os_str(), s.as_os_str()])
        .args(["--method", "icp", "--json", "-"])
        .args(extra)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    serde_json::from_slice(&out.stdout).unwrap()
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    [0, 1, 2].map(|k| v[k].as_f64().unwrap())
}

fn rotation_deg(json: &serde_json::Value) -> f64 {
    let w = json["quaternion_wxyz"][0].as_f64().unwrap().abs().min(1.0);
    2.0 * w.acos().to_degrees()
}

#[test]
fn map_coordinates_register_like_the_same_clouds_at_the_origin() {
    let d = dir("utm");
    let (t, s, template) = write_pair(&d, UTM);
    let aligned = d.join("aligned.ply");
    let far = register_icp(&t, &s, &["--aligned", aligned.to_str().unwrap()]);
    let d0 = dir("utm0");
    let (t0, s0, _) = write_pair(&d0, [0.0; 3]);
    let near = register_icp(&t0, &s0, &[]);

    // The shift is found, at map coordinates as at the origin.
    assert!(rotation_deg(&far) < 0.01, "{far}");
    let local = vec3(&far["local_translation"]);
    for k in 0..3 {
        assert!((local[k] + SHIFT[k]).abs() < 1e-4, "{far}");
    }
    assert!((rotation_deg(&far) - rotation_deg(&near)).abs() < 1e-3);
    let local0 = vec3(&near["local_translation"]);
    for k in 0..3 {
        assert!((local[k] - local0[k]).abs() < 1e-5, "{far}\n{near}");
    }
    // The origin is the template's median, in the file's frame.
    let origin = vec3(&far["origin"]);
    for k in 0..3 {
        assert!((origin[k] - UTM[k]).abs() < 1.0, "{origin:?}");
    }

    // The file-frame pose moves the source file's points onto the
    // template's, and --aligned .ply holds exactly those points in f64.
    let m = &far["matrix"];
    let apply = |p: [f64; 3]| -> [f64; 3] {
        [0, 1, 2].map(|r| {
            (0..3)
                .map(|c| m[r][c].as_f64().unwrap() * p[c])
                .sum::<f64>()
                + m[r][3].as_f64().unwrap()
        })
    };
    let written = ply::parse_f64_limited(&std::fs::read(&aligned).unwrap(), usize::MAX).unwrap();
    assert_eq!(written.len(), template.len());
    for (i, (w, t)) in written.iter().zip(&template).enumerate() {
        let moved = apply([0, 1, 2].map(|k| t[k] + SHIFT[k]));
        for k in 0..3 {
            assert!((w[k] - t[k]).abs() < 1e-3, "point {i}: {w:?} vs {t:?}");
            // The matrix printed and the points written agree to within the
            // rotation's lever arm over the file's origin (|R - I| x 5.4e6).
            assert!(
                (moved[k] - t[k]).abs() < 1.0,
                "point {i}: {moved:?} vs {t:?}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&d0);
}

#[test]
fn aligned_output_takes_the_format_of_its_extension() {
    let d = dir("aligned-formats");
    let (t, s, _) = write_pair(&d, [0.0; 3]);
    for (name, magic) in [
        ("a.pcd", &b"# .PCD"[..]),
        ("a.ply", b"ply\n"),
        ("a.xyz", b""),
        ("a.off", b"OFF\n"),
    ] {
        let path = d.join(name);
        register_icp(&t, &s, &["--aligned", path.to_str().unwrap()]);
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(magic), "{name}");
        let format = Format::from_path(&path).unwrap();
        let points = format.parse(&bytes).unwrap();
        assert_eq!(points.len(), 512, "{name}");
    }
    let bad = d.join("a.las");
    let out = Command::new(env!("CARGO_BIN_EXE_pcrnet"))
        .args(["register".as_ref(), t.as_os_str(), s.as_os_str()])
        .args(["--method", "icp", "--aligned", bad.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("use the extension .pcd, .ply"), "{stderr}");
    let _ = std::fs::remove_dir_all(&d);
}

/// What the writers write, the readers read back bit for bit, in f32 and
/// in f64, in every format.
#[test]
fn writers_round_trip_exactly() {
    let f64s: Vec<[f64; 3]> = vec![
        [0.1, -2.5e-8, 5_400_000.123_456_789],
        [-0.0, 1e300, f64::MIN_POSITIVE],
        [123.456, 7.0, -8.25],
    ];
    let f32s: Vec<[f32; 3]> = vec![[0.1, -2.5e-8, 3.4e38], [-0.0, 1e-40, 7.0]];
    for format in [
        Format::Pcd,
        Format::Ply,
        Format::Xyz,
        Format::Csv,
        Format::Off,
    ] {
        let read = |bytes: &[u8]| -> Vec<[f64; 3]> {
            match format {
                Format::Pcd => pcd::parse_f64_limited(bytes, 10).unwrap(),
                Format::Ply => ply::parse_f64_limited(bytes, 10).unwrap(),
                Format::Xyz | Format::Csv => xyz::parse_f64_limited(bytes, 10).unwrap(),
                Format::Off => off::parse_limited(bytes, 10).unwrap().vertices,
                Format::F32 => pcrnet_io::raw::parse_f64_limited(bytes, 10).unwrap(),
            }
        };
        let back = read(&encode(format, &f64s));
        for (b, p) in back.iter().zip(&f64s) {
            assert_eq!(b.map(f64::to_bits), p.map(f64::to_bits), "{format}");
        }
        let back = format.parse(&encode(format, &f32s)).unwrap();
        for (b, p) in back.iter().zip(&f32s) {
            assert_eq!(b.map(f32::to_bits), p.map(f32::to_bits), "{format}");
        }
    }
    // Raw .f32 holds f32 only: f32 clouds come back bit for bit.
    let back = Format::F32.parse(&encode(Format::F32, &f32s)).unwrap();
    assert_eq!(back.len(), f32s.len());
    for (b, p) in back.iter().zip(&f32s) {
        assert_eq!(b.map(f32::to_bits), p.map(f32::to_bits));
    }
}

/// Reading about an origin: the median by default, exactly the f32
/// reading with the origin at zero, and points that do not fit f32 about
/// it dropped.
#[test]
fn local_reading_keeps_what_f32_loses() {
    let text = "500000.25 5400000.01 0\n500000.75 5400000.02 0\n500000.50 5400000.03 1\n";
    let local = Format::Xyz.parse_local(text.as_bytes(), 10, None).unwrap();
    assert_eq!(local.origin, [500_000.5, 5_400_000.02, 0.0]);
    let ys: Vec<f32> = local.points.iter().map(|p| p[1]).collect();
    assert!((ys[0] + 0.01).abs() < 1e-6 && ys[1] == 0.0 && (ys[2] - 0.01).abs() < 1e-6);
    // Rounded to f32 in the file's frame, the three northings are one value.
    let flat = Format::Xyz.parse(text.as_bytes()).unwrap();
    assert!(flat.iter().all(|p| p[1] == flat[0][1]));
    let at_zero = Format::Xyz
        .parse_local(text.as_bytes(), 10, Some([0.0; 3]))
        .unwrap();
    assert_eq!(at_zero.points, flat);
    let huge = "1e300 0 0\n1 2 3\n";
    let local = Format::Xyz
        .parse_local(huge.as_bytes(), 10, Some([0.0; 3]))
        .unwrap();
    assert_eq!(local.points, vec![[1.0, 2.0, 3.0]]);
}
