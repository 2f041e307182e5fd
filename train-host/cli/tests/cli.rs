//! The `pcrnet` binary as a user's shell runs it: bad flag values and a
//! closed output pipe give a clear exit, never a panic.

use std::path::PathBuf;
use std::process::{Command, Stdio};

fn pcrnet() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pcrnet"))
}

fn models() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

#[test]
fn a_closed_output_pipe_ends_quietly() {
    let m = models();
    let runs: [Vec<PathBuf>; 2] = [
        vec![
            "register".into(),
            m.join("embedded-default-template.xyz"),
            m.join("embedded-default-source.xyz"),
            "--method".into(),
            "icp".into(),
        ],
        vec!["inspect".into(), m.join("embedded-default-int8.pcrn")],
    ];
    for args in runs {
        let mut child = pcrnet()
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The reader goes away before anything is written (`| head -0`).
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
    }
}

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

#[test]
fn bad_flag_values_are_errors_naming_the_flag() {
    for (args, flag) in [
        (
            vec![
                "pairs",
                "--generated",
                "3",
                "--max-deg=-10",
                "--out",
                "/dev/null",
            ],
            "--max-deg",
        ),
        (
            vec![
                "pairs",
                "--generated",
                "3",
                "--max-deg",
                "nan",
                "--out",
                "/dev/null",
            ],
            "--max-deg",
        ),
        (
            vec![
                "pairs",
                "--generated",
                "3",
                "--max-t",
                "nan",
                "--out",
                "/dev/null",
            ],
            "--max-t",
        ),
        (
            vec![
                "train",
                "--generated",
                "3",
                "--max-t",
                "nan",
                "--out",
                "/dev/null",
            ],
            "--max-t",
        ),
    ] {
        let out = pcrnet().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains(flag) && !stderr.contains("panicked"),
            "{args:?}: {stderr}"
        );
        // One chain of messages, no backtrace even when one is asked for.
        assert!(!stderr.contains("stack backtrace"), "{stderr}");
    }
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

/// Issue 10, item 15: training prints each epoch as it ends, with the time
/// left, and an --out folder holding an earlier run is refused unless the
/// run is resumed or replaced on purpose.
#[test]
fn training_reports_epochs_and_guards_its_output_folder() {
    let dir = std::env::temp_dir().join(format!("pcrnet-cli-train-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let train = |extra: &[&str]| {
        pcrnet()
            .args([
                "train",
                "--generated",
                "4",
                "--arch",
                "8,16:16",
                "--points",
                "64",
            ])
            .args(["--batch", "2", "--epochs", "2", "--steps-per-epoch", "1"])
            .arg("--out")
            .arg(&dir)
            .args(extra)
            .output()
            .unwrap()
    };
    let out = train(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let first = stderr.find("epoch   1/2:").expect("epoch 1 reported");
    let second = stderr.find("epoch   2/2:").expect("epoch 2 reported");
    assert!(first < second && stderr.contains("s left"), "{stderr}");
    let log = std::fs::read_to_string(dir.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2);

    let out = train(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("holds an earlier run") && stderr.contains("--force"));
    assert_eq!(std::fs::read_to_string(dir.join("log.jsonl")).unwrap(), log);

    let out = train(&["--force"]);
    assert_eq!(out.status.code(), Some(0));
    let log = std::fs::read_to_string(dir.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2, "one run's log, not two mixed");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 10, items 12 and 13, as a kind: every user error is one chain of
/// messages in the user's terms (the flag or file it concerns, what to do),
/// no backtrace even with RUST_BACKTRACE=1, no part said twice.
#[test]
fn user_errors_name_the_flag_or_file_once() {
    let m = models();
    let s = |p: &str| m.join(p).display().to_string();
    let (src, tpl) = (
        s("embedded-default-source.xyz"),
        s("embedded-default-template.xyz"),
    );
    let (int8, f32) = (
        s("embedded-default-int8.pcrn"),
        s("embedded-default-f32.pcrn"),
    );
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "register".into(),
                src.clone(),
                "--method".into(),
                "pointnetlk".into(),
                "--model".into(),
                int8.clone(),
            ],
            "--method pointnetlk needs the f32 blob",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                src.clone(),
            ],
            "not a model blob",
        ),
        (
            vec![
                "register".into(),
                tpl.clone(),
                src.clone(),
                "--model".into(),
                f32.clone(),
                "--hypotheses".into(),
                "0".into(),
            ],
            "--hypotheses must be at least 1",
        ),
        (
            vec![
                "register".into(),
                tpl.clone(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--template-points".into(),
                "70000".into(),
            ],
            "--template-points must be between 1 and 65535",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--template-points".into(),
                "1024".into(),
            ],
            "--template-points applies to a TEMPLATE file",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--icp-distance=nan".into(),
            ],
            "--icp-distance NaN",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--method".into(),
                "icp".into(),
            ],
            "give TEMPLATE SOURCE",
        ),
        (
            vec![
                "pairs".into(),
                "--generated".into(),
                "2".into(),
                "--noise".into(),
                "abc".into(),
                "--out".into(),
                "/nonexistent/p.json".into(),
            ],
            "--noise \"abc\"",
        ),
        (
            vec!["inspect".into(), "/nonexistent.pcrn".into()],
            "/nonexistent.pcrn",
        ),
        // More starting poses than the template has turns (+ 1), with the
        // blob's own template and with a template file bound in its place.
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--hypotheses".into(),
                "99".into(),
            ],
            "--hypotheses 99: the template has 9 turns, so the device tries 1 to 10",
        ),
        (
            vec![
                "register".into(),
                tpl.clone(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--hypotheses".into(),
                "11".into(),
            ],
            "--hypotheses 11: the template has 9 turns",
        ),
        // A negative value after a space reaches the flag's own check.
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--max-residual".into(),
                "-1".into(),
            ],
            "--max-residual -1 must be finite and at least 0",
        ),
        // Refused once, before any pair is read.
        (
            vec![
                "eval".into(),
                "--pairs".into(),
                "/nonexistent/pairs.json".into(),
                "--method".into(),
                "device".into(),
            ],
            "--method device needs a model",
        ),
    ];
    for (args, expected) in cases {
        let out = pcrnet()
            .args(&args)
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("backtrace") && !stderr.contains("panicked"));
        let line = stderr.lines().find(|l| l.starts_with("error: ")).unwrap();
        let parts: Vec<&str> = line.split(": ").filter(|p| p.len() > 12).collect();
        for (i, p) in parts.iter().enumerate() {
            assert!(!parts[i + 1..].contains(p), "said twice: {line}");
        }
    }
}

/// What a reader or the trainer leaves out or cannot use is said: points
/// with a non-finite coordinate are counted, and an object that fixes no
/// pose is refused before any epoch runs (nothing is written).
#[test]
fn left_out_points_and_unusable_objects_are_said() {
    let dir = std::env::temp_dir().join(format!("pcrnet-cli-said-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let nan = dir.join("nan.xyz");
    let rows = "nan 0 0\n0.1 0.2 0.3\n0 nan 1\n0.5 0.1 0.2\n0.2 0.4 0.1\n0.3 -0.2 0.1\n";
    std::fs::write(&nan, rows).unwrap();
    let model = models().join("embedded-default-int8.pcrn");
    let out = pcrnet()
        .args([
            "register".as_ref(),
            nan.as_os_str(),
            "--model".as_ref(),
            model.as_os_str(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("2 of 6 points left out"), "{stderr}");
    for (name, rows, expected) in [
        ("one.xyz", "1 2 3\n", "has no extent"),
        ("line.xyz", "0 0 0\n1 0 0\n2 0 0\n3 0 0\n", "lie on a line"),
    ] {
        let (object, run) = (dir.join(name), dir.join(format!("run-{name}")));
        std::fs::write(&object, rows).unwrap();
        let out = pcrnet()
            .args(["train".as_ref(), "--object".as_ref(), object.as_os_str()])
            .args(["--epochs", "1", "--out"])
            .arg(&run)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {stderr}");
        assert!(stderr.contains(expected), "{name}: {stderr}");
        let written = std::fs::read_dir(&run).map_or(0, |d| d.count());
        assert_eq!(written, 0, "{name}: training wrote into {}", run.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 11, item 1: `pcrnet train --object FILE` trains for one object in
/// its own units, end to end, and the blob it writes registers that
/// object's clouds in those units.
#[test]
fn training_for_ones_own_object_end_to_end() {
    use pcrnet_train::shapes::{Shape, sample};
    let dir = std::env::temp_dir().join(format!("pcrnet-cli-object-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A part 50 mm across, 2 m from the origin, in millimetres.
    let part: String = sample(Shape::Ell, 400, 2)
        .iter()
        .map(|p| format!("{} {} {}\n", 2000.0 + 50.0 * p[0], 50.0 * p[1], 50.0 * p[2]))
        .collect();
    let object = dir.join("part.xyz");
    std::fs::write(&object, part).unwrap();
    let out_dir = dir.join("model");
    let out = pcrnet()
        .arg("train")
        .arg("--object")
        .arg(&object)
        .args(["--arch", "8,16:16", "--points", "64", "--batch", "4"])
        .args(["--epochs", "2", "--steps-per-epoch", "2", "--no-progress"])
        .args(["--single-view", "--resample", "--template-points", "64"])
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("1 training shapes, 1 validation shapes"),
        "{stderr}"
    );
    assert!(stderr.contains("2 steps/epoch x 2 epochs"), "{stderr}");
    assert!(stderr.contains("epoch   2/2:"), "{stderr}");
    for blob in ["model-int8.pcrn", "model-f32.pcrn"] {
        assert!(out_dir.join(blob).is_file(), "{blob}: {stderr}");
    }
    // The blob stores the whole 64-point template, as the guide asks.
    let out = pcrnet()
        .arg("inspect")
        .arg(out_dir.join("model-int8.pcrn"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("template: 64 points with normals"),
        "{stdout}"
    );
    let out = pcrnet()
        .arg("register")
        .arg(&object)
        .arg("--model")
        .arg(out_dir.join("model-int8.pcrn"))
        .args(["--json", "-"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // The blob's frame is the part's: its own cloud is in range, nothing
    // clipped or left out, and the untrained pose still lands near it.
    assert_eq!(json["out_of_range"], 0, "{json}");
    let t = &json["translation"];
    assert!(t[0].as_f64().unwrap().abs() < 2000.0, "{json}");
    // Scoring it on poses of the same part, single-view and resampled.
    let pairs = dir.join("pairs.json");
    let out = pcrnet()
        .arg("pairs")
        .arg("--object")
        .arg(&object)
        .args([
            "--points",
            "64",
            "--count",
            "6",
            "--single-view",
            "--resample",
        ])
        .arg("--out")
        .arg(&pairs)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = pcrnet()
        .arg("eval")
        .arg("--pairs")
        .arg(&pairs)
        .args(["--method", "device", "--template-points", "64", "--model"])
        .arg(out_dir.join("model-int8.pcrn"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("(6 pairs)")
            && stdout.contains("AUC")
            && stdout.contains("64-point template"),
        "{stdout}"
    );
    assert!(!stdout.contains("failed"), "{stdout}");
    // Without --points, an object's pairs take train --object's 1,024.
    let out = pcrnet()
        .arg("pairs")
        .arg("--object")
        .arg(&object)
        .args(["--count", "2", "--out"])
        .arg(&pairs)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let set: serde_json::Value = serde_json::from_slice(&std::fs::read(&pairs).unwrap()).unwrap();
    assert_eq!(set["spec"]["points"], 1024, "{}", set["spec"]);
    // Training from resampled sources needs points left over.
    let out = pcrnet()
        .arg("train")
        .arg("--object")
        .arg(&object)
        .args(["--points", "400", "--resample", "--epochs", "1", "--out"])
        .arg(dir.join("no-rest"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("part.xyz: no points left to resample")
            && stderr.contains("lower --points"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 11, item 6: several `--data` roots and generated shapes train as
/// one set, `--classes` naming classes of any root (a one-class root is
/// named after its folder).
#[test]
fn training_on_several_roots_and_generated_shapes() {
    use pcrnet_train::shapes::{Shape, sample};
    let dir = std::env::temp_dir().join(format!("pcrnet-cli-roots-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let write = |path: std::path::PathBuf, seed: u64| {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let text: String = sample(Shape::Torus, 80, seed)
            .iter()
            .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
            .collect();
        std::fs::write(path, text).unwrap();
    };
    // Root A: classes "cup" (2 train, 1 test) and "pot" (1 train, 1 test).
    let a = dir.join("A");
    write(a.join("cup/train/c1.xyz"), 1);
    write(a.join("cup/train/c2.xyz"), 2);
    write(a.join("cup/test/c3.xyz"), 3);
    write(a.join("pot/train/p1.xyz"), 4);
    write(a.join("pot/test/p2.xyz"), 5);
    // Root B: one class named after the folder (3 train, 1 test).
    let b = dir.join("B");
    for i in 0..3 {
        write(b.join(format!("train/b{i}.xyz")), 10 + i);
    }
    write(b.join("test/b9.xyz"), 19);
    let out = pcrnet()
        .arg("train")
        .arg("--data")
        .arg(&a)
        .arg("--data")
        .arg(&b)
        .args([
            "--generated",
            "4",
            "--classes",
            "cup,B",
            "--arch",
            "8,16:16",
        ])
        .args([
            "--points",
            "64",
            "--batch",
            "4",
            "--epochs",
            "1",
            "--no-progress",
        ])
        .arg("--out")
        .arg(dir.join("model"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    // 2 cups + 3 of B + 4 generated; validation 1 + 1 + 1.
    assert!(
        stderr.contains("9 training shapes, 3 validation shapes"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `pcrnet inspect --c-header` writes exactly the header the minimal C
/// firmware commits (so a stale one is caught here), `--rust` the same
/// figures, and an f32 blob is refused naming why.
#[test]
fn inspect_writes_the_model_sizes_for_firmware() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let run = |args: &[&str]| pcrnet().current_dir(&root).args(args).output().unwrap();
    let c = run(&["inspect", "models/embedded-default-int8.pcrn", "--c-header"]);
    assert_eq!(c.status.code(), Some(0));
    let committed = std::fs::read(root.join("examples/minimal-c/model_sizes.h")).unwrap();
    assert_eq!(
        String::from_utf8_lossy(&c.stdout),
        String::from_utf8_lossy(&committed),
        "examples/minimal-c/model_sizes.h is stale: regenerate it with pcrnet inspect --c-header"
    );
    let rust = run(&["inspect", "models/embedded-default-int8.pcrn", "--rust"]);
    let text = String::from_utf8_lossy(&rust.stdout);
    assert!(
        text.contains("pub const BLOB_LEN: usize = 229602;"),
        "{text}"
    );
    let f32 = run(&["inspect", "models/embedded-default-f32.pcrn", "--c-header"]);
    assert_eq!(f32.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&f32.stderr).contains("not an int8 model blob"));
}

/// `pcrnet convert` writes the shipped XYZ source as the very `.f32` the
/// firmware links, and reads it back to the same points.
#[test]
fn convert_writes_the_firmware_f32_format() {
    let m = models();
    let dir = std::env::temp_dir().join(format!("pcrnet-convert-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (f32, back) = (dir.join("source.f32"), dir.join("back.xyz"));
    for (input, output) in [
        (m.join("embedded-default-source.xyz"), &f32),
        (f32.clone(), &back),
    ] {
        let out = pcrnet()
            .arg("convert")
            .arg(&input)
            .arg(output)
            .output()
            .unwrap();
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert_eq!(
        std::fs::read(&f32).unwrap(),
        std::fs::read(m.join("embedded-default-source.f32")).unwrap()
    );
    let a = pcrnet_io::read_cloud(&m.join("embedded-default-source.xyz")).unwrap();
    assert_eq!(pcrnet_io::read_cloud(&back).unwrap(), a);
    std::fs::write(dir.join("bad.f32"), [0u8; 13]).unwrap();
    let out = pcrnet()
        .arg("convert")
        .arg(dir.join("bad.f32"))
        .arg(dir.join("x.xyz"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("multiple of 12"));
    std::fs::remove_dir_all(&dir).unwrap();
}
