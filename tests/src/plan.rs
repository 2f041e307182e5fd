//! What the harness runs: the models of each case set, their clouds and
//! the option sets `register` runs with ([`models`]), and the cases built
//! from them ([`build_cases`]).

use std::path::PathBuf;

use anyhow::Context;
use pcrnet_core::{Frame, Int8Model, MAX_TILE, Metric, Options};

use crate::hostile;
use crate::qemu::{self, CaseSet};
use crate::vectors::{
    Case, TestModel, clouds_for, doubled, jittered, random_model, random_model_with, read_cloud,
    with_lk_solver,
};

/// The shipped model that gets the realistic sources.
const SHIPPED_DEFAULT: &str = "embedded-default-int8.pcrn";

/// The label of the shipped model's noisy source: its demo source with
/// every coordinate jittered uniformly by `0.01 x sqrt(3)` (standard deviation
/// 0.01 of the template's size, the `trust` experiment's noise), where the
/// right pose's residual is the noise's, not near 0.
pub const NOISY: &str = "noisy demo source";

/// Half-width of the noisy source's uniform jitter: `0.01 x sqrt(3)`.
const NOISY_JITTER: f32 = 0.017_320_5;

/// The shipped model's encoder with a random PointNetLK solver and no
/// head (no PointNetLK model is shipped): PointNetLK's cost at the
/// embedded size, on the 512-point demo source.
pub const SHIPPED_LK: &str = "embedded-default encoder, random LK solver (headless)";

/// A model, the sizes of its uniform clouds, its realistic sources, and
/// the option sets `register` runs with on its small (<= 300 points) and
/// invalid clouds and on its realistic sources.
pub struct Plan {
    /// The model.
    pub model: TestModel,
    /// Point counts of its uniform (generated) clouds.
    pub sizes: Vec<usize>,
    /// Realistic sources, labelled.
    pub sources: Vec<(String, Vec<[f32; 3]>)>,
    /// Option sets `register` runs with on the small, invalid and realistic clouds.
    pub options: Vec<Options>,
}

/// Network only, and the recommended pipeline (`Options::default()`).
fn net_and_default() -> Vec<Options> {
    vec![Options::network_only(), Options::default()]
}

/// Network only, K=1 and K=4 with the default ICP, and the default pipeline.
fn net_k1_k4_default() -> Vec<Options> {
    let k = |hypotheses| Options {
        hypotheses,
        ..Options::default()
    };
    vec![Options::network_only(), k(1), k(4), Options::default()]
}

/// The default options scoring and refining up to 512 points (every point
/// of the demo source): what a tracker that wants the last half degree
/// runs (the `tracking` experiment's 512-point rows).
pub fn every_point() -> Options {
    Options {
        max_points: 512,
        ..Options::default()
    }
}

/// Every field away from its default (i-PCRNet passes stopping early,
/// three hypotheses screened with 3 ICP iterations before the finalists
/// get 10, fewer points): the screening path, and a check that the
/// options reach the device intact.
fn unusual_options() -> Options {
    Options {
        passes: 3,
        tolerance: 0.01,
        hypotheses: 3,
        screen_iterations: 3,
        icp_iterations: 10,
        metric: Metric::PointToPoint,
        icp_tolerance: 2e-3,
        icp_distance: 0.2,
        inlier_distance: 0.1,
        max_points: 64,
        network_points: 48,
        max_residual: 0.05,
        // LK steps need a blob with PointNetLK's solver: the LK models'
        // own option sets run them.
        lk_iterations: 0,
    }
}

/// PointNetLK alone: `steps` LK steps from the centring start, the start
/// kept (one hypothesis, no ICP), on a headless blob's sample
/// (`registration::network_points(false)`, as `trained_options` sets it).
pub fn lk_only(steps: usize) -> Options {
    Options {
        passes: 0,
        lk_iterations: steps,
        network_points: pcrnet_core::registration::network_points(false),
        ..Options::network_only()
    }
}

/// `passes` network passes, then `steps` LK steps, then the default
/// hypotheses and ICP; the sample of a blob with a head when `passes > 0`,
/// else a headless one's.
fn lk_then_default(passes: usize, steps: usize) -> Options {
    Options {
        passes,
        lk_iterations: steps,
        network_points: pcrnet_core::registration::network_points(passes > 0),
        ..Options::default()
    }
}

/// A headless PointNetLK blob's option sets: LK alone, LK then the
/// default ICP, and the default options, which ask for a network pass
/// (`NoHead` on both sides).
fn headless_lk_options() -> Vec<Options> {
    vec![lk_only(5), lk_then_default(0, 5), Options::default()]
}

/// Invalid options: `register` must fail the same way on both sides.
fn invalid_options() -> Options {
    Options {
        hypotheses: 0,
        ..Options::default()
    }
}

/// Centimetres, 2.5 m / -0.4 m / 10 m from the origin: the random models'
/// input range (+-4 model units) is +-4 m around that centre.
const CM_FRAME: Frame = Frame {
    centre: [250.0, -40.0, 1000.0],
    scale: 0.01,
};

/// The random models with a PointNetLK solver: one headless (centred
/// sources, frame in centimetres), registering by LK alone, and one with a
/// head, refining its network pass by LK.
fn random_lk_plans() -> Vec<Plan> {
    vec![
        Plan {
            model: with_lk_solver(
                &random_model_with("", 7, &[16, 32, 64], &[], true, CM_FRAME).blob,
                "random 16-32-64 / - PointNetLK (headless, random solver), frame cm, centred sources",
                70,
                true,
            ),
            sizes: vec![1, 64, 256],
            sources: Vec::new(),
            options: headless_lk_options(),
        },
        Plan {
            model: with_lk_solver(
                &random_model("", 8, &[16, 32, 64], &[64, 32]).blob,
                "random 16-32-64 / 64-32 + random LK solver",
                80,
                false,
            ),
            sizes: vec![1, 64, 256],
            sources: Vec::new(),
            options: vec![lk_then_default(1, 3), Options::default()],
        },
    ]
}

/// Random models covering the shapes' corners, two with a frame in
/// centimetres far from the origin, two with a random PointNetLK solver
/// (one headless, registering by LK alone; one refining its network pass
/// by LK), every int8 blob shipped in `models/` (the embedded default also
/// with its demo source at 512 and 1024 points, and its encoder with a
/// random solver as [`SHIPPED_LK`]), and the paper-size PCRNet (its 4.2
/// MB of weights go to PSRAM). Boards other than the default run a subset
/// (see [`CaseSet`]).
pub fn models(set: CaseSet) -> anyhow::Result<Vec<Plan>> {
    let plan = |model, sizes: &[usize]| Plan {
        model,
        sizes: sizes.to_vec(),
        sources: Vec::new(),
        options: net_and_default(),
    };
    let mut out = vec![
        plan(
            random_model("random 16-24-64 / 48-32", 1, &[16, 24, 64], &[48, 32]),
            &[1, 2, 3, 7, 8, 9, 16, 31, 257, 1024, 3000],
        ),
        plan(
            random_model("random 8 / - (one layer each)", 2, &[8], &[]),
            &[1, 5, 100],
        ),
        plan(
            random_model(
                "random 8+8 layers",
                3,
                &[24, 24, 24, 24, 24, 24, 24, 96],
                &[64; 8],
            ),
            &[1, 33, 500],
        ),
        plan(
            random_model_with(
                "random 16-32-64 / 64-32, frame cm at (250, -40, 1000)",
                5,
                &[16, 32, 64],
                &[64, 32],
                false,
                CM_FRAME,
            ),
            &[1, 64, 256],
        ),
        plan(
            random_model_with(
                "random 16-32-64 / 64-32, frame cm, centred sources",
                6,
                &[16, 32, 64],
                &[64, 32],
                true,
                CM_FRAME,
            ),
            &[1, 64, 256],
        ),
    ];
    // Not on the micro:bit: the models above fill its 128 KiB data region
    // (128.5 KB with their clouds); the Cortex-M3 and RISC-V boards run
    // PointNetLK's steps in soft float.
    if set != CaseSet::Small {
        out.extend(random_lk_plans());
    }
    let dir = qemu::workspace_root().join("models");
    let mut shipped: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with("-int8.pcrn"))
        .collect();
    shipped.sort();
    for path in shipped {
        let blob = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        let name = path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let mut sources = Vec::new();
        let mut lk = None;
        if name == SHIPPED_DEFAULT {
            let demo = read_cloud(&dir.join("embedded-default-source.f32"))?;
            // LK alone also for one step: a step's cost is the difference.
            let mut options = headless_lk_options();
            options.insert(1, lk_only(1));
            lk = Some(Plan {
                model: with_lk_solver(&blob, SHIPPED_LK, 90, true),
                sizes: vec![1, 100],
                sources: vec![(format!("demo source {}", demo.len()), demo.clone())],
                options,
            });
            let dense = doubled(&demo, 1024, 0.005);
            let noisy = jittered(&demo, 512, NOISY_JITTER);
            let half: Vec<[f32; 3]> = demo.iter().step_by(2).copied().collect();
            sources.push((
                format!("demo source {} (every other point)", half.len()),
                half,
            ));
            sources.push((format!("{NOISY} {}", noisy.len()), noisy));
            sources.push((format!("demo source {}", demo.len()), demo));
            sources.push((
                format!("demo source {} (twice, jitter 0.005)", dense.len()),
                dense,
            ));
        }
        out.push(Plan {
            model: TestModel { name, blob },
            sizes: vec![1, 100, 1024, 4096],
            sources,
            options: net_k1_k4_default()
                .into_iter()
                .chain([every_point()])
                .collect(),
        });
        out.extend(lk);
    }
    out.push(plan(
        random_model(
            "paper PCRNet 64-64-64-128-1024 / 1024-1024-512-512-256 (PSRAM)",
            4,
            pcrnet_core::arch::PAPER_ENCODER,
            pcrnet_core::arch::PCRNET_HEAD,
        ),
        &[1, 9, 1024],
    ));
    let (random_only, largest) = match set {
        CaseSet::Full => (false, usize::MAX),
        CaseSet::Subset => (false, 1024),
        CaseSet::Small => (true, 300),
    };
    // Blobs every loader must refuse alike (no cases; 2.3 MB: not on the
    // micro:bit, whose data region is 128 KiB).
    if set != CaseSet::Small {
        for model in hostile::blobs()? {
            out.push(Plan {
                model,
                sizes: Vec::new(),
                sources: Vec::new(),
                options: Vec::new(),
            });
        }
    }
    out.retain(|p| set == CaseSet::Full || !p.model.name.starts_with("paper"));
    out.retain(|p| !random_only || p.model.name.starts_with("random"));
    for p in &mut out {
        p.sizes.retain(|&n| n <= largest);
    }
    Ok(out)
}

/// The device's models and every case of `plans`: which clouds, tile,
/// i-PCRNet passes and `register` option sets each case runs.
pub fn build_cases(plans: &[Plan]) -> (Vec<TestModel>, Vec<Case>) {
    let mut cases = Vec::new();
    let mut out = Vec::new();
    for (mi, plan) in plans.iter().enumerate() {
        let model = &plan.model;
        let clouds = if plan.sizes.is_empty() {
            Vec::new()
        } else {
            clouds_for(&model.blob, 100 + mi as u64, &plan.sizes)
        };
        let generated = clouds.len();
        let has_solver = Int8Model::from_bytes(&model.blob).is_ok_and(|m| m.lk_solver().is_some());
        let sources = plan.sources.iter().cloned();
        let mut unusual = false;
        for (ci, (label, cloud)) in clouds.into_iter().chain(sources).enumerate() {
            let realistic = ci >= generated;
            // Vary the tile; the measured 1024-point cases use the largest.
            let tile = if cloud.len() == 1024 {
                MAX_TILE
            } else {
                cases.len() % MAX_TILE + 1
            };
            // i-PCRNet passes on the small clouds and every invalid one.
            let small = cloud.len() <= 300;
            let iterations = if small { 3 } else { 0 };
            // `register` on the small and invalid clouds and the realistic
            // sources (the large uniform clouds cost network time only).
            let mut registrations = if small || realistic {
                plan.options.clone()
            } else {
                Vec::new()
            };
            // Once per model, on its first uniform cloud of 9 to 300 points.
            if !unusual && label.starts_with("uniform") && (9..=300).contains(&cloud.len()) {
                registrations.push(unusual_options());
                // LK steps on a blob without a solver: `NoLkSolver` alike.
                if !has_solver {
                    registrations.push(lk_only(2));
                }
                unusual = true;
            }
            if label.starts_with("NaN") {
                registrations.push(invalid_options());
            }
            cases.push(Case {
                model: mi,
                label,
                cloud,
                tile,
                iterations,
                registrations,
            });
        }
        out.push(TestModel {
            name: model.name.clone(),
            blob: model.blob.clone(),
        });
    }
    (out, cases)
}
