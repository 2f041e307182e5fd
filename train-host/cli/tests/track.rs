//! `pcrnet track`: a slowly turning object followed through a folder of
//! frames (the first registered, every next one kept, each within a degree
//! of the truth), and missing frames or an empty folder refused by name.

mod common;

use std::path::{Path, PathBuf};

use common::{models, pcrnet};

/// Frames in the sequence.
const FRAMES: usize = 8;

/// The fixed axis the object turns about (unit length).
fn axis() -> [f64; 3] {
    let a = [1.0, 2.0, 3.0f64];
    let n = a.iter().map(|v| v * v).sum::<f64>().sqrt();
    a.map(|v| v / n)
}

/// The true pose of frame `k` (0-based), mapping the frame onto the
/// template (`p_template = R p_frame + t`): 10 degrees about [`axis`] and 3
/// more each frame, and a small translation growing with it.
fn truth(k: usize) -> ([f64; 4], [f64; 3]) {
    let angle = (10.0 + 3.0 * k as f64).to_radians();
    let (s, c) = (angle / 2.0).sin_cos();
    let [x, y, z] = axis();
    let t = [0.02, -0.01, 0.015].map(|v| v * (k + 1) as f64);
    ([c, x * s, y * s, z * s], t)
}

/// `q` as a rotation matrix (row-major).
fn matrix([w, x, y, z]: [f64; 4]) -> [[f64; 3]; 3] {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The angle between two rotations, degrees.
fn angle_between(a: [f64; 4], b: [f64; 4]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(p, q)| p * q).sum();
    2.0 * dot.abs().min(1.0).acos().to_degrees()
}

/// A fresh, empty folder under the system's temporary one.
fn temp_folder(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pcrnet-track-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The template's points.
fn template_points() -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(models().join("embedded-default-template.xyz")).unwrap();
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// Writes the [`FRAMES`] frames into `dir` as `frame-01.xyz`...: the
/// template's points moved by the inverse of each frame's true pose
/// (`p_frame = R^T (p_template - t)`), and a file that is not a cloud.
fn write_frames(dir: &Path) {
    let template = template_points();
    // Written last to first: the folder's order is the names'.
    for k in (0..FRAMES).rev() {
        let (q, t) = truth(k);
        let r = matrix(q);
        let mut text = String::new();
        for p in &template {
            let d = [p[0] - t[0], p[1] - t[1], p[2] - t[2]];
            let moved = [0, 1, 2].map(|j| r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2]);
            text += &format!("{} {} {}\n", moved[0], moved[1], moved[2]);
        }
        std::fs::write(dir.join(format!("frame-{:02}.xyz", k + 1)), text).unwrap();
    }
    std::fs::write(dir.join("notes.md"), "not a cloud: left out\n").unwrap();
}

/// The frames of a slow, steady motion are registered once and kept after
/// that, every pose within a degree of the truth (the JSON on standard
/// output, the lines and the summary on standard error); `--predict` keeps
/// them too.
#[test]
fn a_slow_motion_is_kept_frame_after_frame() {
    let dir = temp_folder("slow");
    write_frames(&dir);
    let template = models().join("embedded-default-template.xyz");
    let out = pcrnet()
        .arg("track")
        .arg(&template)
        .arg(&dir)
        .args(["--json", "-"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("model: the shipped embedded default (models/embedded-default-int8.pcrn"),
        "{stderr}"
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Every template point stored: no floor to measure.
    assert!(report["template_floor"].is_null(), "{report}");
    assert!(!stderr.contains("template residual floor"), "{stderr}");
    let frames = report["frames"].as_array().unwrap();
    assert_eq!(frames.len(), FRAMES, "{report}");
    for (k, frame) in frames.iter().enumerate() {
        let want = if k == 0 { "registered" } else { "kept" };
        assert_eq!(frame["index"], k + 1, "{frame}");
        assert_eq!(frame["outcome"], want, "{frame}");
        assert_eq!(frame["reliable"], true, "{frame}");
        let file = frame["file"].as_str().unwrap();
        assert!(file.ends_with(&format!("frame-{:02}.xyz", k + 1)), "{file}");
        let q: Vec<f64> = serde_json::from_value(frame["quaternion_wxyz"].clone()).unwrap();
        let t: Vec<f64> = serde_json::from_value(frame["translation"].clone()).unwrap();
        let (q_true, t_true) = truth(k);
        let error = angle_between([q[0], q[1], q[2], q[3]], q_true);
        assert!(error < 1.0, "frame {}: {error} degrees off: {frame}", k + 1);
        for j in 0..3 {
            assert!((t[j] - t_true[j]).abs() < 0.02, "frame {}: {frame}", k + 1);
        }
    }
    let lines: Vec<&str> = stderr.lines().collect();
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("frame 1 frame-01.xyz: registered;")),
        "{stderr}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("frame 8 frame-08.xyz: kept;")),
        "{stderr}"
    );
    assert!(
        stderr.contains(
            "frames: 8, registered: 1, kept: 7, recovered: 0, lost: 0, not reliable: 0; mean "
        ),
        "{stderr}"
    );

    let predicted = pcrnet()
        .arg("track")
        .arg(&template)
        .args((1..=FRAMES).map(|k| dir.join(format!("frame-{k:02}.xyz"))))
        .arg("--predict")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&predicted.stdout).into_owned();
    assert_eq!(predicted.status.code(), Some(0), "{stdout}");
    assert!(
        stdout.contains("frames: 8, registered: 1, kept: 7, recovered: 0, lost: 0"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A frame that does not exist, an empty frame file and a folder without
/// cloud files are refused before any frame is registered, naming the file
/// or folder.
#[test]
fn missing_frames_and_empty_folders_are_named() {
    let dir = temp_folder("errors");
    let template = models().join("embedded-default-template.xyz");
    let source = models().join("embedded-default-source.xyz");
    let track = |frames: &[PathBuf]| {
        let out = pcrnet()
            .arg("track")
            .arg(&template)
            .args(frames)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(out.status.code(), Some(1), "{frames:?}: {stderr}");
        assert!(out.stdout.is_empty(), "{frames:?}: nothing registered");
        assert!(!stderr.contains("panicked"), "{stderr}");
        stderr
    };

    let missing = dir.join("no-such-frame.xyz");
    let stderr = track(&[source.clone(), missing]);
    assert!(
        stderr.contains("no-such-frame.xyz: no such file (frame 2)"),
        "{stderr}"
    );

    let empty_file = dir.join("empty-frame.xyz");
    std::fs::write(&empty_file, "").unwrap();
    let stderr = track(&[source.clone(), empty_file]);
    assert!(
        stderr.contains("empty-frame.xyz: empty file (frame 2)"),
        "{stderr}"
    );

    let empty_folder = dir.join("empty-folder");
    std::fs::create_dir_all(&empty_folder).unwrap();
    std::fs::write(empty_folder.join("notes.md"), "not a cloud").unwrap();
    let stderr = track(std::slice::from_ref(&empty_folder));
    assert!(
        stderr.contains("empty-folder: no cloud files in this folder"),
        "{stderr}"
    );

    let stderr = track(&[source, empty_folder]);
    assert!(
        stderr.contains("empty-folder: a folder among 2 frames"),
        "{stderr}"
    );

    // No frame at all is a usage error (status 2), as clap gives them.
    let out = pcrnet().arg("track").arg(&template).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("<FRAME>"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A template stored sparsely (64 of its 512 points) has a residual floor
/// measured on the other 448 and carried in the bound blob: `track` uses
/// the blob's verdict, calibrated by it, unless `--max-residual` is given,
/// and says which; the JSON carries the floor and the verdict in force.
#[test]
fn a_sparse_template_calibrates_the_verdict_by_its_residual_floor() {
    use pcrnet_core::registration::{NOISE_ALLOWANCE, max_residual_for};
    let run = |extra: &[&str]| {
        let out = pcrnet()
            .arg("track")
            .arg(models().join("embedded-default-template.xyz"))
            .arg(models().join("embedded-default-source.xyz"))
            .args(["--template-points", "64", "--json", "-"])
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(out.status.code(), Some(0), "{stderr}");
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let floor = report["template_floor"].as_f64().unwrap() as f32;
        let threshold = report["verdict_max_residual"].as_f64().unwrap() as f32;
        (floor, threshold, stderr)
    };
    let (floor, threshold, stderr) = run(&[]);
    assert!(floor > 0.015 && floor < 0.1, "{floor}");
    assert!(
        (threshold - max_residual_for(floor, 0.015)).abs() < 1e-6,
        "{threshold} vs {floor} + {NOISE_ALLOWANCE}"
    );
    assert!(
        stderr.contains("template residual floor: ")
            && stderr.contains("the verdict is calibrated for it"),
        "{stderr}"
    );
    // Asked for the default verdict: kept, with a warning.
    let (again, threshold, stderr) = run(&["--max-residual", "0.015"]);
    assert_eq!(again, floor);
    assert_eq!(threshold, 0.015);
    assert!(
        stderr.contains("may score above the verdict's --max-residual 0.015"),
        "{stderr}"
    );
}
