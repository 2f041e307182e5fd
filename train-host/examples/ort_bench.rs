//! Our half of the side-by-side benchmark against ONNX Runtime (`cargo
//! xtask ort-bench` runs it, then `tools/ort_bench.py`).
//!
//! For the shipped embedded default and a paper-width PCRNet (seeded
//! random weights, quantized like a trained model), it writes to `DIR/<model>/`:
//! - `weights.f32` and `network.json`: the f32 weights (row-major,
//!   outputs x inputs) and biases of every layer, then the template
//!   feature, little-endian; the layer shapes, the frame and whether
//!   sources are centred. The script rebuilds the network from them as an
//!   ONNX graph;
//! - `clouds.f32`: the benchmark clouds (clouds x points x 3, little-endian);
//! - `ours.json`: our per-call times and f32 head outputs.
//!
//! Times: one thread, per call (network pose of one cloud: moving the
//! points into the model frame, centring, encoder, head, quaternion),
//! wall clock; a round is every cloud once, after one warm-up round. Two
//! figures: the median round's time per call and the best (fastest)
//! round's. On a shared machine the median moves with whatever else runs;
//! the best round is the closest either side gets to its own cost, so the
//! script prints the ratios of both.
//!
//! For ICP (issue 13's third target), `DIR/icp/` gets each cloud as a
//! template and a source made from it by the experiments' pairs (Euler
//! angles U[-45°, 45°], translation U[-1, 1], noise 0.01), `truth.json`
//! with the true poses, and `ours.json` with our point-to-point ICP's
//! poses and times (`pcrnet_train::eval::icp`), run for a fixed 50
//! iterations and with its own stop rule; the script runs Open3D's
//! `registration_icp` on the same pairs when Open3D is installed.
//!
//! Usage: `ort_bench DIR [--data MODELNET10_DIR] [--clouds N] [--rounds R]`.
//! Without `--data`, generated shapes stand in for the ModelNet10 clouds.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use pcrnet_core::arch::{PAPER_ENCODER, PCRNET_HEAD};
use pcrnet_core::float::Params;
use pcrnet_core::{Arch, F32Model, Int8Model};
use pcrnet_train::eval::{self, icp::IcpConfig};
use pcrnet_train::shapes::{Shape, random_transform, sample};
use pcrnet_train::template::{DEFAULT_TEMPLATE_POINTS, Reference};
use pcrnet_train::train::data::{self, PairConfig, Sampling};
use pcrnet_train::train::dataset::{Dataset, Split};
use pcrnet_train::train::geometry::{Mat3, quat_to_mat};
use pcrnet_train::{CalibrationRule, F32Params, TrainedFor, quantize};
use serde_json::json;

const POINTS: usize = 1024;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let mut out = None;
    let (mut data, mut count, mut rounds) = (None, 50usize, 5usize);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().with_context(|| format!("{name} needs a value"));
        match a.as_str() {
            "--data" => data = Some(PathBuf::from(value("--data")?)),
            "--clouds" => count = value("--clouds")?.parse().context("--clouds")?,
            "--rounds" => rounds = value("--rounds")?.parse().context("--rounds")?,
            _ if out.is_none() && !a.starts_with('-') => out = Some(PathBuf::from(a)),
            _ => bail!(
                "unknown argument {a}; usage: ort_bench DIR [--data DIR] [--clouds N] [--rounds R]"
            ),
        }
    }
    let out = out.context("usage: ort_bench DIR [--data DIR] [--clouds N] [--rounds R]")?;
    if count == 0 || rounds == 0 {
        bail!("--clouds and --rounds must be at least 1");
    }
    let (clouds, what) = clouds(data.as_deref(), count)?;
    println!("{} clouds of {POINTS} points ({what})", clouds.len());

    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let f32_blob = std::fs::read(root.join("models/embedded-default-f32.pcrn"))?;
    let int8_blob = std::fs::read(root.join("models/embedded-default-int8.pcrn"))?;
    run("embedded", &f32_blob, &int8_blob, &clouds, rounds, &out)?;

    let (f32_blob, int8_blob) = paper_blobs(&clouds)?;
    run("paper", &f32_blob, &int8_blob, &clouds, rounds, &out)?;
    icp(&clouds, rounds, &out)?;
    std::fs::write(out.join("clouds.txt"), what)?;
    Ok(())
}

type Cloud = Vec<[f32; 3]>;

/// Iterations of the fixed-work ICP comparison.
const ICP_ITERATIONS: usize = 50;

/// Our ICP on pairs made from the clouds, for `fixed` iterations (no stop
/// rule) and with our stop rule; writes the pairs, the true poses and our
/// poses and times to `DIR/icp/`.
fn icp(clouds: &[Vec<[f32; 3]>], rounds: usize, out: &Path) -> anyhow::Result<()> {
    let cfg = PairConfig {
        noise: Some([0.01, 0.01]),
        centre: false,
        ..PairConfig::default()
    };
    let pairs: Vec<(Cloud, Mat3, [f32; 3])> = clouds
        .iter()
        .enumerate()
        .map(|(i, c)| data::make_pair(c, &cfg, data::mix_seed(1, 0x1C9, i as u64)))
        .collect();
    let dir = out.join("icp");
    std::fs::create_dir_all(&dir)?;
    let floats = |v: &mut dyn Iterator<Item = &[f32; 3]>| -> Vec<u8> {
        v.flatten().flat_map(|x| x.to_le_bytes()).collect()
    };
    std::fs::write(
        dir.join("template.f32"),
        floats(&mut clouds.iter().flatten()),
    )?;
    std::fs::write(
        dir.join("source.f32"),
        floats(&mut pairs.iter().flat_map(|p| &p.0)),
    )?;
    let truth: Vec<_> = pairs.iter().map(|p| json!({"r": p.1, "t": p.2})).collect();
    std::fs::write(dir.join("truth.json"), serde_json::to_vec(&truth)?)?;

    let mut results = serde_json::Map::new();
    for (name, config) in [
        (
            "fixed",
            IcpConfig {
                max_iterations: ICP_ITERATIONS,
                tolerance: 0.0,
            },
        ),
        ("stop rule", IcpConfig::default()),
    ] {
        let mut poses = Vec::new();
        let mut iterations = Vec::new();
        for (c, p) in clouds.iter().zip(&pairs) {
            let r = eval::icp::icp(c, &p.0, config)?;
            poses.push(json!({"r": quat_to_mat(r.pose.rotation), "t": r.pose.translation}));
            iterations.push(r.iterations);
        }
        let jobs: Vec<(&Cloud, &Cloud)> = clouds.iter().zip(pairs.iter().map(|p| &p.0)).collect();
        let ms = round_ms(rounds, &jobs, |(c, source)| {
            black_box(eval::icp::icp(c, source, config)).is_ok()
        })?;
        println!(
            "ICP ({name}): ours {:.3} ms per registration (best round {:.3})",
            ms.median, ms.best
        );
        results.insert(
            name.into(),
            json!({"ms": ms.median, "best_ms": ms.best, "poses": poses, "iterations": iterations}),
        );
    }
    results.insert("fixed_iterations".into(), json!(ICP_ITERATIONS));
    std::fs::write(dir.join("ours.json"), serde_json::to_vec(&results)?)?;
    Ok(())
}

/// `count` test clouds of a ModelNet-layout root (ModelNet10 by default),
/// preprocessed as for training and evaluation (`Dataset::load_modelnet`:
/// centred, in the unit box), evenly spaced over the classes' sorted
/// files, labelled with the classes they came from; or generated shapes.
fn clouds(data: Option<&Path>, count: usize) -> anyhow::Result<(Vec<Vec<[f32; 3]>>, String)> {
    let Some(root) = data else {
        let set = Dataset::generated(count, POINTS, 1);
        return Ok((set.clouds, "generated shapes".into()));
    };
    let set = Dataset::load_modelnet(root, Split::Test, None, POINTS, Sampling::Random, 1)?;
    let step = (set.clouds.len() / count).max(1);
    let mut classes: Vec<&str> = set.labels.iter().map(String::as_str).collect();
    classes.dedup();
    let label = format!("test split of {}, {}", classes.join(" "), root.display());
    let clouds = set.clouds.into_iter().step_by(step).take(count).collect();
    Ok((clouds, label))
}

/// A paper-width PCRNet with seeded random weights, quantized with
/// calibration clouds as a trained one would be.
fn paper_blobs(clouds: &[Vec<[f32; 3]>]) -> anyhow::Result<(Vec<u8>, Vec<u8>)> {
    let params = F32Params::init(Arch::new(PAPER_ENCODER, PCRNET_HEAD)?, 7);
    let template = sample(Shape::Ell, POINTS, 7);
    let reference = Reference::new(&template, DEFAULT_TEMPLATE_POINTS)?;
    let calibration: Vec<_> = clouds
        .iter()
        .take(16)
        .enumerate()
        .map(|(i, c)| random_transform(c, 45.0, 0.5, i as u64))
        .collect();
    let trained = TrainedFor::pcrnet(true);
    let int8 = quantize(
        &params,
        &reference,
        &calibration,
        CalibrationRule::default(),
        trained,
    )?;
    Ok((params.to_f32_blob(&reference, trained)?, int8))
}

fn run(
    name: &str,
    f32_blob: &[u8],
    int8_blob: &[u8],
    clouds: &[Vec<[f32; 3]>],
    rounds: usize,
    out: &Path,
) -> anyhow::Result<()> {
    let fmodel = F32Model::from_bytes(f32_blob)?;
    let qmodel = Int8Model::from_bytes(int8_blob)?;
    let net = fmodel.network();
    let dir = out.join(name);
    std::fs::create_dir_all(&dir)?;

    // Every layer's weights then biases, then the template feature, as
    // little-endian f32 in `weights.f32`; their shapes in `network.json`.
    let mut weights = Vec::new();
    let mut put = |p: pcrnet_core::float::LeF32<'_>| {
        weights.extend((0..p.len()).flat_map(|i| p.get(i).to_le_bytes()));
    };
    let shapes = net.arch().encoder_layers().chain(net.arch().head_layers());
    let mut layers = Vec::new();
    for (l, s) in net.layers().iter().zip(shapes) {
        put(l.weights);
        put(l.bias);
        layers.push(json!({"inputs": s.inputs, "outputs": s.outputs, "relu": s.relu}));
    }
    put(net.template());
    std::fs::write(dir.join("weights.f32"), weights)?;
    let frame = fmodel.frame();
    let network = json!({
        "encoder_layers": net.arch().encoder.len(),
        "layers": layers,
        "feature": net.arch().feature_dim(),
        "frame_centre": frame.centre,
        "frame_scale": frame.scale,
        "centre_source": fmodel.centres_source(),
    });
    std::fs::write(dir.join("network.json"), serde_json::to_vec(&network)?)?;
    let bytes: Vec<u8> = clouds
        .iter()
        .flatten()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(dir.join("clouds.f32"), bytes)?;

    // The f32 head outputs the script checks ONNX Runtime's against.
    let mut fscratch = vec![0f32; fmodel.tiled_scratch_len()];
    let mut outputs = Vec::new();
    for c in clouds {
        let model_frame: Vec<[f32; 3]> = c.iter().map(|p| frame.to_model(*p)).collect();
        outputs.push(net.infer(&model_frame, &mut fscratch)?.to_vec());
    }
    let mut qscratch = vec![0i8; qmodel.host_scratch_len()];
    let f32_ms = round_ms(rounds, clouds, |c| {
        black_box(fmodel.network_pose(black_box(c), 1, 0.0, &mut fscratch)).is_ok()
    })?;
    let int8_ms = round_ms(rounds, clouds, |c| {
        black_box(qmodel.network_pose(black_box(c), 1, 0.0, &mut qscratch)).is_ok()
    })?;
    println!(
        "{name}: ours f32 {:.3} ms, int8 {:.3} ms per call (best rounds {:.3}, {:.3})",
        f32_ms.median, int8_ms.median, f32_ms.best, int8_ms.best
    );
    let ours = json!({"f32_ms": f32_ms.median, "int8_ms": int8_ms.median,
        "f32_best_ms": f32_ms.best, "int8_best_ms": int8_ms.best, "outputs": outputs,
        "encoder": net.arch().encoder, "head": net.arch().head});
    std::fs::write(dir.join("ours.json"), serde_json::to_vec(&ours)?)?;
    Ok(())
}

/// A timed call's milliseconds per item: the median round's and the best
/// round's.
struct RoundMs {
    median: f64,
    best: f64,
}

/// The time per call of `call` over every item, `rounds` timed rounds
/// after one warm-up round.
fn round_ms<T>(
    rounds: usize,
    clouds: &[T],
    mut call: impl FnMut(&T) -> bool,
) -> anyhow::Result<RoundMs> {
    let mut times = Vec::new();
    for r in 0..=rounds {
        let t = Instant::now();
        let ok = clouds.iter().filter(|c| call(c)).count();
        let per_call = t.elapsed().as_secs_f64() * 1e3 / clouds.len() as f64;
        if ok != clouds.len() {
            bail!(
                "{} of {} benchmark clouds failed",
                clouds.len() - ok,
                clouds.len()
            );
        }
        if r > 0 {
            times.push(per_call);
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().context("no round")?;
    let best = times.first().copied().context("no round")?;
    Ok(RoundMs { median, best })
}
