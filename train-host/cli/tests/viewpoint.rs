//! `pcrnet register --viewpoint`: a single view of the shipped template
//! checked from where its sensor stood. The whole view passes and is
//! reliable; a fragment of it is never reliable; bad viewpoints are errors
//! naming the flag.

mod common;

use std::path::{Path, PathBuf};

use common::{models, pcrnet};
use pcrnet_core::Pose;
use pcrnet_train::view::{eye, visible_from};

/// The view seen from `dir`, moved by a rigid motion, with its viewpoint
/// moved the same way (the files' frame).
fn moved_view(template: &[[f32; 3]], dir: [f32; 3]) -> (Vec<[f32; 3]>, [f32; 3]) {
    let h = 20f32.to_radians() / 2.0;
    let motion = Pose {
        rotation: [h.cos(), 0.6 * h.sin(), 0.0, 0.8 * h.sin()],
        translation: [0.3, -0.2, 0.5],
    };
    let seen: Vec<[f32; 3]> = visible_from(template, dir)
        .into_iter()
        .map(|i| motion.transform_point(template[i]))
        .collect();
    let at = motion.transform_point(eye(template, dir).unwrap());
    (seen, at)
}

fn write_xyz(path: &Path, points: &[[f32; 3]]) {
    let text: String = points
        .iter()
        .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    std::fs::write(path, text).unwrap();
}

fn register(source: &Path, extra: &[&str]) -> (Option<i32>, String, String) {
    let out = pcrnet()
        .arg("register")
        .arg(models().join("embedded-default-template.xyz"))
        .arg(source)
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn point(p: [f32; 3]) -> String {
    format!("{},{},{}", p[0], p[1], p[2])
}

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("pcrnet-viewpoint-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn a_single_view_is_checked_from_its_viewpoint() {
    let template = pcrnet_io::read_cloud(&models().join("embedded-default-template.xyz")).unwrap();
    let (view, at) = moved_view(&template, [0.3, -0.5, 0.81]);
    let d = dir();
    let whole = d.join("view.xyz");
    write_xyz(&whole, &view);
    let (code, stdout, stderr) = register(&whole, &["--viewpoint", &point(at), "--json", "-"]);
    assert_eq!(code, Some(0), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["view_check"]["passed"], true, "{v}");
    assert_eq!(v["reliable"], true, "{v}");
    assert!(stderr.contains("view check from the viewpoint"), "{stderr}");

    // A fifth of the view (the points nearest one of its ends) is a
    // fragment: wherever it fits, the rest of the object's near side would
    // be where the sensor saw nothing.
    let end = view
        .iter()
        .copied()
        .max_by(|a, b| a[0].total_cmp(&b[0]))
        .unwrap();
    let mut by_distance: Vec<[f32; 3]> = view.clone();
    let d2 = |p: &[f32; 3]| (0..3).map(|k| (p[k] - end[k]).powi(2)).sum::<f32>();
    by_distance.sort_by(|a, b| d2(a).total_cmp(&d2(b)));
    by_distance.truncate(view.len() / 5);
    let piece = d.join("piece.xyz");
    write_xyz(&piece, &by_distance);
    let (code, stdout, stderr) = register(&piece, &["--viewpoint", &point(at), "--json", "-"]);
    assert_eq!(code, Some(0), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["view_check"]["passed"], false, "{v}");
    assert_eq!(v["reliable"], false, "{v}");
    let (_, stdout, _) = register(&piece, &["--viewpoint", &point(at)]);
    assert!(
        stdout.contains("where the sensor saw past the object"),
        "{stdout}"
    );

    // Bad viewpoints: a typed error naming what to give.
    let (code, _, stderr) = register(&whole, &["--viewpoint", "1,2"]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("three finite numbers X,Y,Z"), "{stderr}");
    let (code, _, stderr) = register(&whole, &["--viewpoint", "0,0,nan"]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("three finite numbers"), "{stderr}");
    let (code, _, stderr) = register(&whole, &["--viewpoint", &point(at), "--method", "icp"]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("--method device"), "{stderr}");
    let (code, _, stderr) = register(&whole, &["--viewpoint", &point(at), "--refine-icp"]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("--refine-icp"), "{stderr}");
    // Too far for f32, and far enough to be another frame's coordinates.
    let (code, _, stderr) = register(&whole, &["--viewpoint", "1e39,0,0"]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("too far from the clouds"), "{stderr}");
    let (code, _, stderr) = register(&whole, &["--viewpoint", "5e5,5.4e6,0"]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("10,000 source radii"), "{stderr}");
    // Among the points: not a sensor's position.
    let inside = view[0];
    let (code, _, stderr) = register(&whole, &["--viewpoint", &point(inside)]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("viewpoint"), "{stderr}");
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn a_stream_of_views_is_tracked_from_its_viewpoint() {
    let template = pcrnet_io::read_cloud(&models().join("embedded-default-template.xyz")).unwrap();
    let (view, at) = moved_view(&template, [0.3, -0.5, 0.81]);
    let d = dir().join("stream");
    std::fs::create_dir_all(&d).unwrap();
    for k in 0..3 {
        write_xyz(&d.join(format!("frame{k}.xyz")), &view);
    }
    let track = |extra: &[&str]| {
        let out = pcrnet()
            .arg("track")
            .arg(models().join("embedded-default-template.xyz"))
            .arg(&d)
            .args(extra)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, stdout, stderr) = track(&["--viewpoint", &point(at), "--json", "-"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("register_view, track_view"), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let outcomes: Vec<&str> = v["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["outcome"].as_str().unwrap())
        .collect();
    assert_eq!(outcomes, ["registered", "kept", "kept"], "{v}");
    assert!(
        v["frames"]
            .as_array()
            .unwrap()
            .iter()
            .all(|f| f["reliable"] == true),
        "{v}"
    );
    // A viewpoint among the points is refused at the first frame.
    let (code, _, stderr) = track(&["--viewpoint", &point(view[0])]);
    assert_ne!(code, Some(0));
    assert!(stderr.contains("viewpoint"), "{stderr}");
    std::fs::remove_dir_all(d).unwrap();
}
