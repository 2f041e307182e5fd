//! `pcrnet register`: the shipped model by default, the device pipeline's
//! options, large clouds reduced (and said so), and a blob run in another
//! mode than it was trained for named.

mod common;

use std::path::PathBuf;

use common::{models, pcrnet};

/// `pcrnet register TEMPLATE SOURCE` runs on the shipped model when no
/// `--model` is given, says so, and gives the very pose `--model` with the
/// shipped file gives.
#[test]
fn register_uses_the_shipped_model_by_default() {
    let m = models();
    let run = |extra: &[PathBuf]| {
        let out = pcrnet()
            .arg("register")
            .arg(m.join("embedded-default-template.xyz"))
            .arg(m.join("embedded-default-source.xyz"))
            .args(extra)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert_eq!(out.status.code(), Some(0), "{stdout}");
        stdout
    };
    let pose_lines = |text: &str| -> Vec<String> {
        text.lines()
            .filter(|l| l.starts_with("quaternion") || l.starts_with("translation"))
            .map(str::to_owned)
            .collect()
    };
    let default = run(&[]);
    assert!(
        default.contains("model: the shipped embedded default (models/embedded-default-int8.pcrn"),
        "{default}"
    );
    let explicit = run(&["--model".into(), m.join("embedded-default-int8.pcrn")]);
    assert!(!explicit.contains("shipped embedded default"), "{explicit}");
    assert_eq!(pose_lines(&default).len(), 2, "{default}");
    assert_eq!(pose_lines(&default), pose_lines(&explicit));
}

/// Every field of the device pipeline's options can be set from the
/// command line and reaches the pipeline: `--icp-tolerance 0` runs ICP to
/// its iteration limit, a tiny `--inlier-distance` leaves points out of
/// the fitness, `--max-residual 0` calls a small residual unreliable; out
/// of range, each is an error naming its flag.
#[test]
fn device_options_reach_the_pipeline() {
    let m = models();
    let register = |extra: &[&str]| {
        let out = pcrnet()
            .arg("register")
            .arg(m.join("embedded-default-source.xyz"))
            .arg("--model")
            .arg(m.join("embedded-default-int8.pcrn"))
            .args(["--json", "-"])
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{extra:?}: {stderr}");
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let default = register(&[]);
    assert_eq!(default["reliable"], true, "{default}");
    assert_eq!(default["fitness"], 1.0, "{default}");
    let iterations = |r: &serde_json::Value| r["icp_iterations"].as_u64().unwrap();
    let to_the_limit = register(&["--icp-tolerance", "0"]);
    assert!(
        iterations(&to_the_limit) > iterations(&default),
        "{to_the_limit}"
    );
    let tight = register(&["--inlier-distance", "1e-6"]);
    assert!(tight["fitness"].as_f64().unwrap() < 1.0, "{tight}");
    assert_eq!(register(&["--max-residual", "0"])["reliable"], false);
    for (flag, value) in [
        ("--icp-tolerance", "-1"),
        ("--inlier-distance", "0"),
        ("--max-residual", "nan"),
    ] {
        let out = pcrnet()
            .arg("register")
            .arg(m.join("embedded-default-source.xyz"))
            .arg("--model")
            .arg(m.join("embedded-default-int8.pcrn"))
            .arg(format!("{flag}={value}"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{flag}: {stderr}");
        assert!(stderr.contains(flag), "{flag}: {stderr}");
    }
}

/// Issue 10, item 5: a large cloud is reduced before registration (by
/// default to 8,192 points, seeded), says so, and still registers; voxel
/// reduction without a cube size is refused with what to pass.
#[test]
fn large_clouds_are_reduced_and_say_so() {
    let m = models();
    let text = std::fs::read_to_string(m.join("embedded-default-source.xyz")).unwrap();
    let big: String = (0..40).map(|_| text.as_str()).collect();
    let dir = std::env::temp_dir().join(format!("pcrnet-cli-reduce-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("big.xyz");
    std::fs::write(&path, big).unwrap();
    let n = 40 * text.lines().count();
    let run = |extra: &[&str]| {
        pcrnet()
            .arg("register")
            .arg(&path)
            .arg("--model")
            .arg(m.join("embedded-default-int8.pcrn"))
            .args(extra)
            .output()
            .unwrap()
    };
    let out = run(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains(&format!("{n} points, 8192 kept (Random")),
        "{stderr}"
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("trust: RELIABLE"));
    let out = run(&["--reduce", "fps", "--reduce-to", "1000"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!("{n} points, 1000 kept (Fps")),
        "{stderr}"
    );
    let out = run(&["--reduce", "voxel"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--voxel SIZE"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 10, item 9: iterating a blob trained for one pass is named, in
/// `register` as in `eval`, with what to run instead.
#[test]
fn running_a_blob_in_another_mode_than_trained_warns() {
    let m = models();
    let out = pcrnet()
        .arg("register")
        .arg(m.join("embedded-default-source.xyz"))
        .args(["--method", "ipcrnet", "--iterations", "2", "--model"])
        .arg(m.join("embedded-default-int8.pcrn"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("warning: this model was trained for one pass (PCRNet); --method ipcrnet"),
        "{stderr}"
    );
    let out = pcrnet()
        .arg("register")
        .arg(m.join("embedded-default-source.xyz"))
        .args(["--method", "pcrnet", "--model"])
        .arg(m.join("embedded-default-int8.pcrn"))
        .output()
        .unwrap();
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
}

/// With the device method, a template file with twice the points stored
/// has its residual floor measured at binding, and the verdict is
/// calibrated by it unless `--max-residual` is given, as `track` does; the
/// JSON says which verdict was in force. Another method has no verdict.
#[test]
fn the_device_verdict_is_calibrated_by_the_templates_residual_floor() {
    use pcrnet_core::registration::max_residual_for;
    let m = models();
    let run = |extra: &[&str]| {
        let stored = if extra.contains(&"--template-points") {
            &[][..]
        } else {
            &["--template-points", "64"][..]
        };
        let out = pcrnet()
            .arg("register")
            .arg(m.join("embedded-default-template.xyz"))
            .arg(m.join("embedded-default-source.xyz"))
            .args(["--json", "-"])
            .args(stored)
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(out.status.code(), Some(0), "{stderr}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        (v, stderr)
    };
    let (v, stderr) = run(&[]);
    let floor = v["template_floor"].as_f64().unwrap() as f32;
    let threshold = v["verdict_max_residual"].as_f64().unwrap() as f32;
    assert!(floor > 0.015, "{v}");
    assert!(
        (threshold - max_residual_for(floor, 0.015)).abs() < 1e-6,
        "{v}"
    );
    assert!(
        stderr.contains("the verdict is calibrated for it"),
        "{stderr}"
    );
    // The verdict reported is the one applied.
    let residual = v["relative_plane_residual"].as_f64().unwrap() as f32;
    assert_eq!(v["reliable"].as_bool(), Some(residual <= threshold), "{v}");
    let (v, _) = run(&["--max-residual", "0.015"]);
    assert_eq!(v["verdict_max_residual"].as_f64(), Some(0.015), "{v}");
    // Every template point stored: nothing measured, the default verdict.
    let (v, stderr) = run(&["--template-points", "512"]);
    assert!(v["template_floor"].is_null(), "{v}");
    assert_eq!(v["verdict_max_residual"].as_f64(), Some(0.015), "{v}");
    assert!(!stderr.contains("residual floor"), "{stderr}");
    let (v, _) = run(&["--method", "icp"]);
    assert!(v.get("template_floor").is_none(), "{v}");
}
