//! `pcrnet train`: epochs reported as they end, the output folder guarded,
//! what a reader or the trainer leaves out said, one's own object trained
//! end to end, and several data roots with generated shapes as one set.

mod common;

use common::{models, pcrnet};

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
        .args(["--up", "-y"])
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
    // And the up axis given (format 7), for `register --scene`.
    assert!(
        stdout.contains("up axis: [0.0, -1.0, 0.0] (template frame)"),
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
