//! `pcrnet frame` and `pcrnet register --scene`: the generated frame's
//! object found standing turned 200 degrees (with --up), within 5 degrees
//! of the pose it was drawn at, the result as JSON; bad flags refused by name.

mod common;

use common::{models, pcrnet};
use pcrnet_core::Int8Model;
use pcrnet_core::testing::scene as harness;

#[test]
fn the_generated_frame_gives_the_object_s_pose() {
    let dir = std::env::temp_dir().join(format!("pcrnet-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("frame.png");
    let out = pcrnet()
        .args(["frame", "--out"])
        .arg(&png)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json = dir.join("frame.json");
    assert!(json.is_file());

    // `register --scene` on the frame with `extra` flags, its JSON result.
    let register = |extra: &[&std::ffi::OsStr]| -> serde_json::Value {
        let out = pcrnet()
            .args(["register", "--scene"])
            .arg(&png)
            .arg("--intrinsics")
            .arg(&json)
            .args(extra)
            .args(["--json", "-"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let v = register(&["--up".as_ref(), "z".as_ref()]);
    assert_eq!(v["reliable"], true, "{v}");
    let q: Vec<f64> = v["quaternion_wxyz"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    // The pose the frame was drawn at (template -> camera); the result maps
    // the camera frame onto the template: its inverse.
    let blob = std::fs::read(models().join("embedded-default-int8.pcrn")).unwrap();
    let model = Int8Model::from_bytes(&blob).unwrap();
    let mut depth = vec![0u16; harness::HARNESS_WIDTH * harness::HARNESS_HEIGHT];
    let mut template = vec![[0f32; 3]; model.template().len()];
    let truth = harness::harness_frame(&model, &mut template, &mut depth)
        .unwrap()
        .inverse();
    // The raw pixels beside the PNG are the frame's, little-endian.
    let raw = std::fs::read(dir.join("frame.u16")).unwrap();
    let pixels: Vec<u16> = raw
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    assert_eq!(pixels, depth);
    let d: f64 = q
        .iter()
        .zip(truth.rotation)
        .map(|(a, b)| a * f64::from(b))
        .sum();
    let error = 2.0 * d.abs().min(1.0).acos().to_degrees();
    assert!(error < 5.0, "{error} deg off: {v}");
    // Whether the winner is one of several poses that fit, and how.
    assert!(v["ambiguity"]["ambiguous"].is_boolean(), "{v}");
    let candidates = v["candidates"].as_array().unwrap();
    assert!(!candidates.is_empty() && candidates.len() <= 3);
    assert_eq!(v["up"], serde_json::json!([0.0, 0.0, 1.0]), "{v}");

    // The same model exported with the up axis (format 7): no --up needed.
    use pcrnet_core::format::{self, ModelKind, Trailer};
    let trailer = Trailer {
        table: model.template().table(),
        up: Some([0.0, 0.0, 1.0]),
        ..Trailer::default()
    };
    let mut with_up = vec![0u8; format::blob_len(model.payload(), &trailer).unwrap()];
    format::write_blob(ModelKind::Int8, model.payload(), &trailer, &mut with_up).unwrap();
    let blob_path = dir.join("with-up.pcrn");
    std::fs::write(&blob_path, &with_up).unwrap();
    let stored = register(&["--model".as_ref(), blob_path.as_os_str()]);
    assert_eq!(stored["up"], v["up"], "{stored}");
    assert_eq!(stored["quaternion_wxyz"], v["quaternion_wxyz"], "{stored}");
    assert_eq!(stored["reliable"], true, "{stored}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn scene_flags_are_checked() {
    let dir = std::env::temp_dir().join(format!("pcrnet-scene-flags-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("frame.png");
    assert!(
        pcrnet()
            .args(["frame", "--out"])
            .arg(&png)
            .status()
            .unwrap()
            .success()
    );
    let run = |args: &[&str]| {
        let out = pcrnet().arg("register").args(args).output().unwrap();
        assert!(!out.status.success(), "{args:?} was accepted");
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let frame = png.to_str().unwrap();
    let e = run(&["--scene", frame]);
    assert!(e.contains("--intrinsics"), "{e}");
    let intrinsics = dir.join("frame.json");
    let with_intrinsics = |flags: &[&str]| {
        let mut args = vec![
            "--scene",
            frame,
            "--intrinsics",
            intrinsics.to_str().unwrap(),
        ];
        args.extend_from_slice(flags);
        run(&args)
    };
    let e = with_intrinsics(&["--up", "w"]);
    assert!(e.contains("not an axis"), "{e}");
    let e = with_intrinsics(&["--candidates", "9"]);
    assert!(e.contains("--candidates"), "{e}");
    let e = run(&["--scene", frame, "--method", "icp"]);
    assert!(e.contains("--method device"), "{e}");
    let cloud = dir.join("cloud.xyz");
    std::fs::write(&cloud, "0 0 1\n0 1 1\n1 0 1\n").unwrap();
    let e = run(&["--scene", cloud.to_str().unwrap()]);
    assert!(e.contains("organised PCD"), "{e}");
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{\"fx\": 1}").unwrap();
    let e = run(&["--scene", frame, "--intrinsics", bad.to_str().unwrap()]);
    assert!(e.contains("not an intrinsics file"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
