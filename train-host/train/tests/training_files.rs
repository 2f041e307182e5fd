//! What the trainer reads and writes on disk: ModelNet-style data folders,
//! checkpoints (and a run resumed from one), and the exported blobs.

mod common;

use std::path::PathBuf;

use common::{bits, data_sets, small_config};
use pcrnet_core::{Arch, F32Model, Int8Model, MAX_TILE, Options};
use pcrnet_train::TrainedFor;
use pcrnet_train::model::ModelKind;
use pcrnet_train::template::Reference;
use pcrnet_train::{
    Checkpoint, Dataset, RunOptions, Sampling, Split, TrainConfig, Trainer, data, export,
};

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pcrnet-train-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An interrupted run resumed from its last checkpoint ends with exactly
/// the weights, optimiser state and log of an uninterrupted run.
#[test]
fn resume_equals_uninterrupted() {
    let (train, val) = data_sets(64);
    let cfg = TrainConfig {
        checkpoint_every: 2,
        model: ModelKind::Ipcrnet { iterations: 2 },
        ..small_config()
    };
    let full_dir = tmp_dir("full");
    let mut full = Trainer::new(cfg.clone(), train.clone(), val.clone()).unwrap();
    let full_sum = full
        .run(&RunOptions {
            out_dir: Some(full_dir.clone()),
            ..RunOptions::default()
        })
        .unwrap();
    assert_eq!(full_sum.epochs.len(), 2);
    assert!(full.finished());

    // Interrupted after 5 steps (checkpoints at steps 2, 3 (epoch end) and 4).
    let dir = tmp_dir("interrupted");
    let mut first = Trainer::new(cfg, train.clone(), val.clone()).unwrap();
    let opts = RunOptions {
        out_dir: Some(dir.clone()),
        max_steps: Some(5),
        ..RunOptions::default()
    };
    first.run(&opts).unwrap();
    assert_eq!(first.progress.global_step, 5);
    let ck = Checkpoint::load(&dir.join(pcrnet_train::CHECKPOINT_FILE)).unwrap();
    assert_eq!(ck.progress.global_step, 4);
    let mut resumed = Trainer::from_checkpoint(ck, train, val).unwrap();
    let rest = resumed
        .run(&RunOptions {
            out_dir: Some(dir.clone()),
            ..RunOptions::default()
        })
        .unwrap();
    assert_eq!(rest.step_seconds.len(), 2);
    assert_eq!(bits(&resumed.params), bits(&full.params));
    assert_eq!(resumed.adam, full.adam);
    assert_eq!(resumed.progress, full.progress);
    // The last checkpoint on disk is the final state.
    let last = Checkpoint::load(&dir.join(pcrnet_train::CHECKPOINT_FILE)).unwrap();
    assert_eq!(last, full.checkpoint());
    // The log lines agree apart from wall time.
    let log = |d: &PathBuf| -> Vec<serde_json::Value> {
        std::fs::read_to_string(d.join(pcrnet_train::LOG_FILE))
            .unwrap()
            .lines()
            .map(|l| {
                let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
                v["seconds"] = serde_json::Value::Null;
                v
            })
            .collect()
    };
    assert_eq!(log(&full_dir), log(&dir));
    let _ = std::fs::remove_dir_all(&full_dir);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A ModelNet-style folder of files loads by class and split.
#[test]
fn a_folder_of_data_roots_is_refused() {
    // As `../shared/data`: one root of classes beside one single-class root.
    let root = tmp_dir("roots");
    for dir in ["mn/a/train", "air/train"] {
        let dir = root.join(dir);
        std::fs::create_dir_all(&dir).unwrap();
        let pts = pcrnet_train::shapes::sample(pcrnet_train::shapes::Shape::Ell, 40, 0);
        let text: String = pts
            .iter()
            .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
            .collect();
        std::fs::write(dir.join("x.xyz"), text).unwrap();
    }
    let e = Dataset::load_modelnet(&root, Split::Train, None, 32, Sampling::Random, 1).unwrap_err();
    assert!(
        matches!(&e, pcrnet_train::dataset::DataError::NestedRoot { inner, .. } if inner.ends_with("mn")),
        "{e}"
    );
    assert!(e.to_string().contains("pass one root"), "{e}");
    // A class that is not there is named, with the ones that are.
    let classes = ["chiar".to_string()];
    let e = Dataset::load_modelnet(
        &root.join("mn"),
        Split::Train,
        Some(&classes[..]),
        32,
        Sampling::Random,
        1,
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("no cloud file of class chiar; its classes are a"),
        "{e}"
    );
    // Each root alone loads.
    for (dir, label) in [("mn", "a"), ("air", "air")] {
        let d =
            Dataset::load_modelnet(&root.join(dir), Split::Train, None, 32, Sampling::Random, 1)
                .unwrap();
        assert_eq!(d.labels, vec![label]);
    }
}

#[test]
fn loads_modelnet_folder() {
    let root = tmp_dir("modelnet");
    for (class, split, k) in [("a", "train", 2), ("a", "test", 1), ("b", "train", 1)] {
        let dir = root.join(class).join(split);
        std::fs::create_dir_all(&dir).unwrap();
        for i in 0..k {
            let pts = pcrnet_train::shapes::sample(pcrnet_train::shapes::Shape::Ell, 40, i);
            let text: String = pts
                .iter()
                .map(|p| format!("{} {} {}\n", p[0] * 10.0 + 3.0, p[1] * 10.0, p[2] * 10.0))
                .collect();
            std::fs::write(dir.join(format!("{class}_{i}.xyz")), text).unwrap();
        }
    }
    let all = Dataset::load_modelnet(&root, Split::Train, None, 32, Sampling::Random, 1).unwrap();
    assert_eq!(all.len(), 3);
    assert_eq!(all.labels, vec!["a", "a", "b"]);
    assert!(all.clouds.iter().all(|c| c.len() == 32));
    let only_b = Dataset::load_modelnet(
        &root,
        Split::Train,
        Some(&["b".to_string()]),
        64,
        Sampling::Fps,
        1,
    )
    .unwrap();
    assert_eq!(only_b.labels, vec!["b"]);
    assert_eq!(only_b.clouds[0].len(), 64);
    let test = Dataset::load_modelnet(&root, Split::Test, None, 32, Sampling::Fps, 1).unwrap();
    assert_eq!(test.len(), 1);
    assert!(
        Dataset::load_modelnet(
            &root,
            Split::Test,
            Some(&["zz".into()]),
            8,
            Sampling::Fps,
            1
        )
        .is_err()
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// Checkpoints round-trip, are replaced atomically, and damage is detected;
/// export writes blobs that `pcrnet-core` loads.
#[test]
fn checkpoint_and_export() {
    let (train, val) = data_sets(64);
    let mut t = Trainer::new(small_config(), train.clone(), val).unwrap();
    t.step();
    let dir = tmp_dir("ckpt");
    let path = dir.join("c.bin");
    let ck = t.checkpoint();
    ck.save(&path).unwrap();
    assert!(!dir.join("c.bin.tmp").exists());
    assert_eq!(Checkpoint::load(&path).unwrap(), ck);
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&path, &bytes).unwrap();
    assert!(Checkpoint::load(&path).is_err());
    std::fs::write(&path, b"nonsense").unwrap();
    assert!(Checkpoint::load(&path).is_err());

    let tpl = &train.clouds[0];
    let cal = export::calibration_clouds(tpl, &t.config.pairs, 8, 1);
    let reference = Reference::new(tpl, 256).unwrap();
    let written = export::export(
        &t.params,
        &reference,
        Some(&cal),
        TrainedFor::pcrnet(true),
        &dir,
    )
    .unwrap();
    assert_eq!(written.len(), 2);
    let f = std::fs::read(dir.join(export::F32_BLOB)).unwrap();
    let m = F32Model::from_bytes(&f).unwrap();
    let mut s = vec![0.0; m.scratch_len()];
    let (src, _, _) = data::make_pair(tpl, &t.config.pairs, 9);
    m.register(&src, &Options::default(), &mut s).unwrap();
    let q = std::fs::read(dir.join(export::INT8_BLOB)).unwrap();
    let m = Int8Model::from_bytes(&q).unwrap();
    let mut s = vec![0i8; m.scratch_len(MAX_TILE)];
    m.register(&src, &Options::default(), &mut s).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_model_with_non_finite_weights_is_not_written() {
    let mut params = pcrnet_train::F32Params::init(Arch::new(&[8, 16], &[16]).unwrap(), 3);
    params.layers[1].0[5] = f32::NAN;
    let tpl = pcrnet_train::shapes::sample(pcrnet_train::shapes::Shape::Ell, 64, 1);
    let reference = Reference::new(&tpl, 64).unwrap();
    let dir = std::env::temp_dir().join(format!("pcrnet-nan-{}", std::process::id()));
    let e = export::export(&params, &reference, None, TrainedFor::pcrnet(true), &dir).unwrap_err();
    assert!(e.to_string().contains("layer 1"), "{e}");
    assert!(!dir.join(export::F32_BLOB).exists());
}

/// A PointNetLK run ends with blobs without a head and with PointNetLK's
/// solver: both load, refuse a network pass with the typed `NoHead`, and
/// register by LK steps; the f32 blob's stored `P` is the one recomputed
/// from the f32 parameters by the training code's own Jacobian.
#[test]
fn a_pointnetlk_checkpoint_exports_headless_blobs_with_a_solver() {
    let (train, val) = data_sets(64);
    let cfg = TrainConfig {
        model: ModelKind::PointNetLk { iterations: 2 },
        ..small_config()
    };
    let dir = tmp_dir("pointnetlk");
    let mut t = Trainer::new(cfg, train.clone(), val).unwrap();
    t.run(&RunOptions {
        out_dir: Some(dir.clone()),
        ..RunOptions::default()
    })
    .unwrap();
    let tpl = &train.clouds[0];
    let cal = export::calibration_clouds(tpl, &t.config.pairs, 8, 1);
    let reference = Reference::new(tpl, 256).unwrap();
    let trained = TrainedFor::pointnetlk(true, 2);
    export::export(&t.params, &reference, Some(&cal), trained, &dir).unwrap();
    let (src, _, _) = data::make_pair(tpl, &t.config.pairs, 9);
    let lk = Options {
        passes: 0,
        lk_iterations: 5,
        ..Options::default()
    };

    let f = std::fs::read(dir.join(export::F32_BLOB)).unwrap();
    let m = F32Model::from_bytes(&f).unwrap();
    assert!(!m.network().has_head());
    assert_eq!(m.trained_passes(), 2);
    let mut s = vec![0.0; m.tiled_scratch_len()];
    assert_eq!(
        m.register(&src, &Options::default(), &mut s),
        Err(pcrnet_core::Error::NoHead)
    );
    let r = m.register(&src, &lk, &mut s).unwrap();
    assert_eq!((r.passes, r.lk_iterations), (0, 5));
    // The stored P against the training code's LK solver on the f32
    // encoder (its own moves, in f64): the same to f32 rounding.
    let stored: Vec<f32> =
        pcrnet_core::format::le_f32s(m.lk_solver().unwrap().stored().rows).collect();
    let params = pcrnet_train::F32Params::from_network(m.network());
    let mut centred = reference.normalised();
    data::centre_cloud(&mut centred);
    let phi = params.encode(&centred).unwrap();
    let moved: Vec<nalgebra::DVector<f64>> = pcrnet_train::lk::moved_templates(&centred)
        .iter()
        .map(|c| {
            nalgebra::DVector::from_iterator(
                phi.len(),
                params.encode(c).unwrap().iter().map(|&v| v as f64),
            )
        })
        .collect();
    let phi = nalgebra::DVector::from_iterator(phi.len(), phi.iter().map(|&v| v as f64));
    let p = pcrnet_train::lk::LkSolver::from_features(&phi, std::array::from_fn(|k| &moved[k]))
        .pseudo_inverse();
    let largest = p.iter().fold(0f64, |m, v| m.max(v.abs()));
    for k in 0..6 {
        for j in 0..phi.len() {
            let (a, b) = (stored[k * phi.len() + j] as f64, p[(k, j)]);
            assert!(
                (a - b).abs() <= 1e-3 * largest,
                "P[{k}][{j}]: stored {a}, recomputed {b}"
            );
        }
    }

    let q = std::fs::read(dir.join(export::INT8_BLOB)).unwrap();
    let m = Int8Model::from_bytes(&q).unwrap();
    assert!(!m.has_head() && m.lk_solver().is_some());
    let trained = m.trained_options();
    assert_eq!((trained.passes, trained.lk_iterations), (0, 2));
    let mut s = vec![0i8; m.scratch_len(MAX_TILE)];
    assert_eq!(
        m.register(&src, &Options::default(), &mut s),
        Err(pcrnet_core::Error::NoHead)
    );
    let r = m.register(&src, &lk, &mut s).unwrap();
    assert_eq!((r.passes, r.lk_iterations), (0, 5));
    let _ = std::fs::remove_dir_all(&dir);
}
