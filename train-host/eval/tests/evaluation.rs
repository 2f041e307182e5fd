//! The evaluation path end to end on generated shapes (no data folder
//! needed): saved pair sets -> every method -> metrics -> RESULTS.md.

use pcrnet_core::Arch;
use pcrnet_eval::experiments::render_results;
use pcrnet_eval::methods::{Method, MethodKind, run};
use pcrnet_eval::pairs::{Pair, PairSet, PairSetSpec, Shapes};
use pcrnet_eval::report::{Provenance, Report, Table};
use pcrnet_eval::score;
use pcrnet_train::data::{PairConfig, Sampling};
use pcrnet_train::shapes::random_transform;
use pcrnet_train::template::Reference;
use pcrnet_train::{CalibrationRule, F32Params, TrainedFor, quantize};

fn temp_dir(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("pcrnet-eval-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn pairs(max_deg: f32, max_t: f32, count: usize) -> Vec<Pair> {
    let spec = PairSetSpec {
        shapes: Shapes::Generated { count: 6 },
        points: 256,
        sampling: Sampling::Random,
        pairs: PairConfig {
            max_deg,
            max_t,
            ..PairConfig::default()
        },
        count,
        seed: 5,
        resample: false,
    };
    let shapes = spec.load_shapes().unwrap();
    PairSet::generate(spec, &shapes)
        .materialise(&shapes)
        .unwrap()
}

/// A random (untrained) model with a centring flag, as int8 and f32 blobs.
fn blobs() -> (Vec<u8>, Vec<u8>) {
    let params = F32Params::init(Arch::new(&[16, 32, 64], &[64, 32]).unwrap(), 3);
    let template = pairs(45.0, 1.0, 1)[0].template.clone();
    let cal: Vec<_> = (0..16)
        .map(|i| random_transform(&template, 45.0, 1.0, 100 + i))
        .collect();
    let reference = Reference::new(&template, 256).unwrap();
    let int8 = quantize(
        &params,
        &reference,
        &cal,
        CalibrationRule::default(),
        TrainedFor::pcrnet(true),
    )
    .unwrap();
    let f32 = params
        .to_f32_blob(&reference, TrainedFor::pcrnet(true))
        .unwrap();
    (int8, f32)
}

#[test]
fn every_method_scores_deterministically() {
    let set = pairs(45.0, 1.0, 8);
    let (int8, f32) = blobs();
    let cases = [
        (Method::new(MethodKind::Pcrnet), Some(&int8)),
        (Method::new(MethodKind::Pcrnet), Some(&f32)),
        (Method::new(MethodKind::Ipcrnet), Some(&int8)),
        (Method::new(MethodKind::Pointnetlk), Some(&f32)),
        (Method::new(MethodKind::Icp), None),
        (Method::new(MethodKind::Pcrnet).then_icp(), Some(&int8)),
    ];
    for (m, blob) in cases {
        let model = blob.map(|b| ("m", b.as_slice()));
        let a = score(&m, model, &set, true).unwrap();
        let b = score(&m, model, &set, false).unwrap();
        assert_eq!(a.summary.count, 8);
        // Parallel and sequential runs give the same errors (times differ).
        let errs = |s: &pcrnet_eval::MethodScore| {
            s.pairs
                .iter()
                .map(|p| (p.rot_deg, p.trans, p.iterations))
                .collect::<Vec<_>>()
        };
        assert_eq!(errs(&a), errs(&b), "{}", a.method);
        assert!(
            (0.0..=1.0).contains(&a.summary.auc),
            "{} {}",
            a.method,
            a.summary.auc
        );
        assert!(
            a.summary.time_ms.unwrap().mean > 0.0,
            "{} {:?}",
            a.method,
            a.failures
        );
    }
}

#[test]
fn icp_and_refinement_are_exact_on_small_clean_offsets() {
    let set = pairs(5.0, 0.05, 6);
    let icp = score(&Method::new(MethodKind::Icp), None, &set, true).unwrap();
    assert!(
        icp.summary.rotation_deg.max < 0.05,
        "{:?}",
        icp.summary.rotation_deg
    );
    assert!(icp.summary.translation.max < 1e-3);
    assert_eq!(icp.summary.success[0].ratio, 1.0);
    assert!(icp.summary.auc > 0.99);
}

#[test]
fn one_pass_ipcrnet_is_pcrnet() {
    let set = pairs(45.0, 1.0, 6);
    let (int8, f32) = blobs();
    let one = Method {
        iterations: 1,
        ..Method::new(MethodKind::Ipcrnet)
    };
    for p in &set {
        let a = run(
            &Method::new(MethodKind::Pcrnet),
            Some(&int8),
            Some(&p.template),
            &p.source,
            None,
        )
        .unwrap();
        let b = run(&one, Some(&int8), Some(&p.template), &p.source, None).unwrap();
        assert_eq!(a.pose, b.pose);
        let c = run(
            &Method::new(MethodKind::Pcrnet),
            Some(&f32),
            Some(&p.template),
            &p.source,
            None,
        )
        .unwrap();
        let d = run(&one, Some(&f32), Some(&p.template), &p.source, None).unwrap();
        assert_eq!(c.pose, d.pose);
    }
}

#[test]
fn results_markdown_shows_tables_plots_and_what_is_missing() {
    let dir = temp_dir("results");
    let report = Report {
        name: "noise".into(),
        title: "Gaussian noise on the source".into(),
        setup: vec!["a setup line".into()],
        tables: vec![Table {
            caption: "Errors".into(),
            header: vec!["noise".into(), "AUC".into()],
            rows: vec![vec!["sigma 0.00".into(), "0.987".into()]],
        }],
        plots: vec!["noise-auc.png".into()],
        runs: Vec::new(),
        provenance: Provenance {
            commit: "abc".into(),
            machine: "test machine".into(),
            data: "../shared/data".into(),
            seed: 1,
            pairs: 200,
            models: vec![("mn10".into(), "pcrnet train ...".into())],
            seconds: 12.0,
        },
    };
    std::fs::write(
        dir.join("noise.json"),
        serde_json::to_string(&report).unwrap(),
    )
    .unwrap();
    let md = render_results(&dir).unwrap();
    assert!(md.contains("## Gaussian noise on the source (`noise`)"));
    assert!(md.contains("| sigma 0.00 | 0.987 |"));
    assert!(md.contains("noise-auc.png"));
    assert!(md.contains("commit `abc`"));
    assert!(md.contains(
        "Not run yet: generalisation, partial, sparse, speed, iterations, trust, resampled, heldout, tracking, scene, ambiguity."
    ));
    std::fs::remove_dir_all(dir).ok();
}
