//! Our half of the side-by-side benchmark against ONNX Runtime and Open3D
//! (`cargo xtask ort-bench` runs it, then `tools/ort_bench.py` and
//! `tools/icp_bench.py`, which time both sides round by round).
//!
//! `ort_bench DIR [--data MODELNET10_DIR] [--clouds N]` writes, for the
//! shipped embedded default and a paper-width PCRNet (seeded random
//! weights, quantized like a trained model), to `DIR/<model>/`:
//! - `weights.f32` and `network.json`: the f32 weights (row-major,
//!   outputs x inputs) and biases of every layer, then the template
//!   feature, little-endian; the layer shapes, the frame and whether
//!   sources are centred. The script rebuilds the network from them as an
//!   ONNX graph;
//! - `f32.pcrn`, `int8.pcrn`: the two blobs `serve` times;
//! - `clouds.f32`: the benchmark clouds (clouds x points x 3, little-endian);
//! - `ours.json`: our f32 head outputs, which ONNX Runtime's must match.
//!
//! For ICP (issue 13's third target), `DIR/icp/` gets each cloud as a
//! template and a source made from it by the experiments' pairs (Euler
//! angles U[-45°, 45°], translation U[-1, 1], noise 0.01), `truth.json`
//! with the true poses, and `ours.json` with our point-to-point ICP's
//! poses (`pcrnet_eval::icp`), run for a fixed 50 iterations and
//! with its own stop rule.
//!
//! `ort_bench serve DIR` then reads what that wrote and times one round
//! per request: a line `embedded f32`, `embedded int8`, `paper f32`,
//! `paper int8`, `icp fixed` or `icp stop` on standard input runs every
//! cloud (or pair) once and answers with one line, the round's wall-clock
//! milliseconds per call; a malformed request ends it with an error. One
//! call is `network_pose` (moving the points into the model frame,
//! centring, encoder, head, quaternion) or one ICP registration. The
//! scripts keep this process waiting between rounds and alternate its
//! rounds with their own, so both sides are timed under the same state of
//! the machine.
//!
//! Without `--data`, generated shapes stand in for the ModelNet10 clouds.

use std::hint::black_box;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use pcrnet_core::arch::{PAPER_ENCODER, PCRNET_HEAD};
use pcrnet_core::float::Params;
use pcrnet_core::{Arch, F32Model, Int8Model};
use pcrnet_eval::icp::{self, IcpConfig};
use pcrnet_train::data::{self, PairConfig, Sampling};
use pcrnet_train::dataset::{Dataset, Split};
use pcrnet_train::geometry::{Mat3, quat_to_mat};
use pcrnet_train::shapes::{Shape, random_transform, sample};
use pcrnet_train::template::{DEFAULT_TEMPLATE_POINTS, Reference};
use pcrnet_train::{CalibrationRule, F32Params, TrainedFor, quantize};
use serde_json::json;

const POINTS: usize = 1024;

const USAGE: &str = "usage: ort_bench DIR [--data DIR] [--clouds N], or ort_bench serve DIR";

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1).peekable();
    if args.next_if_eq("serve").is_some() {
        let dir = args.next().context(USAGE)?;
        return serve(Path::new(&dir));
    }
    let mut out = None;
    let (mut data, mut count) = (None, 50usize);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().with_context(|| format!("{name} needs a value"));
        match a.as_str() {
            "--data" => data = Some(PathBuf::from(value("--data")?)),
            "--clouds" => count = value("--clouds")?.parse().context("--clouds")?,
            _ if out.is_none() && !a.starts_with('-') => out = Some(PathBuf::from(a)),
            _ => bail!("unknown argument {a}; {USAGE}"),
        }
    }
    let out = out.context(USAGE)?;
    if count == 0 {
        bail!("--clouds must be at least 1");
    }
    let (clouds, what) = clouds(data.as_deref(), count)?;
    println!("{} clouds of {POINTS} points ({what})", clouds.len());

    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let f32_blob = std::fs::read(root.join("models/embedded-default-f32.pcrn"))?;
    let int8_blob = std::fs::read(root.join("models/embedded-default-int8.pcrn"))?;
    write_network("embedded", &f32_blob, &int8_blob, &clouds, &out)?;

    let (f32_blob, int8_blob) = paper_blobs(&clouds)?;
    write_network("paper", &f32_blob, &int8_blob, &clouds, &out)?;
    write_icp(&clouds, &out)?;
    std::fs::write(out.join("clouds.txt"), what)?;
    Ok(())
}

type Cloud = Vec<[f32; 3]>;

/// Iterations of the fixed-work ICP comparison.
const ICP_ITERATIONS: usize = 50;

/// The two ICP settings compared: a fixed number of iterations (no stop
/// rule), and our stop rule; by their `serve` names.
fn icp_config(name: &str) -> Option<IcpConfig> {
    match name {
        "fixed" => Some(IcpConfig {
            max_iterations: ICP_ITERATIONS,
            tolerance: 0.0,
        }),
        "stop" => Some(IcpConfig::default()),
        _ => None,
    }
}

/// Pairs made from the clouds, and our ICP's poses on them with each
/// setting of [`icp_config`]: writes the pairs, the true poses and our
/// poses to `DIR/icp/`.
fn write_icp(clouds: &[Vec<[f32; 3]>], out: &Path) -> anyhow::Result<()> {
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
    std::fs::write(dir.join("template.f32"), floats(clouds))?;
    let sources: Vec<Cloud> = pairs.iter().map(|p| p.0.clone()).collect();
    std::fs::write(dir.join("source.f32"), floats(&sources))?;
    let truth: Vec<_> = pairs.iter().map(|p| json!({"r": p.1, "t": p.2})).collect();
    std::fs::write(dir.join("truth.json"), serde_json::to_vec(&truth)?)?;

    let mut results = serde_json::Map::new();
    for name in ["fixed", "stop"] {
        let config = icp_config(name).context("an ICP setting")?;
        let mut poses = Vec::new();
        let mut iterations = Vec::new();
        for (c, source) in clouds.iter().zip(&sources) {
            let r = icp::icp(c, source, config)?;
            poses.push(json!({"r": quat_to_mat(r.pose.rotation), "t": r.pose.translation}));
            iterations.push(r.iterations);
        }
        results.insert(
            name.into(),
            json!({"poses": poses, "iterations": iterations}),
        );
    }
    results.insert("fixed_iterations".into(), json!(ICP_ITERATIONS));
    std::fs::write(dir.join("ours.json"), serde_json::to_vec(&results)?)?;
    Ok(())
}

/// Clouds as little-endian f32 (clouds x points x 3).
fn floats(clouds: &[Cloud]) -> Vec<u8> {
    clouds
        .iter()
        .flatten()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// Clouds of [`POINTS`] points each read back from [`floats`]' layout.
fn read_clouds(path: &Path) -> anyhow::Result<Vec<Cloud>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    if bytes.len() % (12 * POINTS) != 0 {
        bail!("{}: not whole clouds of {POINTS} points", path.display());
    }
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let points: Vec<[f32; 3]> = values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    Ok(points.chunks(POINTS).map(<[_]>::to_vec).collect())
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

/// Writes one network's weights, shapes, blobs, clouds and f32 head
/// outputs to `DIR/<name>/`.
fn write_network(
    name: &str,
    f32_blob: &[u8],
    int8_blob: &[u8],
    clouds: &[Vec<[f32; 3]>],
    out: &Path,
) -> anyhow::Result<()> {
    let fmodel = F32Model::from_bytes(f32_blob)?;
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
    std::fs::write(dir.join("clouds.f32"), floats(clouds))?;
    std::fs::write(dir.join("f32.pcrn"), f32_blob)?;
    std::fs::write(dir.join("int8.pcrn"), int8_blob)?;

    // The f32 head outputs the script checks ONNX Runtime's against.
    let mut fscratch = vec![0f32; fmodel.tiled_scratch_len()];
    let mut outputs = Vec::new();
    for c in clouds {
        let model_frame: Vec<[f32; 3]> = c.iter().map(|p| frame.to_model(*p)).collect();
        outputs.push(net.infer(&model_frame, &mut fscratch)?.to_vec());
    }
    let ours = json!({"outputs": outputs, "encoder": net.arch().encoder, "head": net.arch().head});
    std::fs::write(dir.join("ours.json"), serde_json::to_vec(&ours)?)?;
    Ok(())
}

/// Answers timing requests (see the module docs) until standard input
/// ends.
fn serve(dir: &Path) -> anyhow::Result<()> {
    let read =
        |path: PathBuf| std::fs::read(&path).with_context(|| format!("reading {}", path.display()));
    let names = ["embedded", "paper"];
    let mut blobs = Vec::new();
    for name in names {
        blobs.push((
            read(dir.join(name).join("f32.pcrn"))?,
            read(dir.join(name).join("int8.pcrn"))?,
        ));
    }
    // Models, scratch and clouds made once, and the int8 model prepared on
    // its scratch once (as ONNX Runtime's session is): a round times the
    // calls alone.
    let mut int8 = Vec::new();
    for (_, int8_blob) in &blobs {
        let q = Int8Model::from_bytes(int8_blob)?;
        let scratch = vec![0i8; q.host_scratch_len()];
        int8.push((q, scratch));
    }
    let mut networks = Vec::new();
    for ((name, (f32_blob, _)), (q, qscratch)) in names.into_iter().zip(&blobs).zip(&mut int8) {
        let f = F32Model::from_bytes(f32_blob)?;
        let fscratch = vec![0f32; f.tiled_scratch_len()];
        let q = q.prepare(qscratch)?;
        let clouds = read_clouds(&dir.join(name).join("clouds.f32"))?;
        networks.push((name, f, q, fscratch, clouds));
    }
    let templates = read_clouds(&dir.join("icp/template.f32"))?;
    let sources = read_clouds(&dir.join("icp/source.f32"))?;
    let pairs: Vec<_> = templates.iter().zip(&sources).collect();
    let mut out = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let line = line?;
        let (what, setting) = line.split_once(' ').unwrap_or((line.as_str(), ""));
        let ms = if what == "icp" {
            let config =
                icp_config(setting).with_context(|| format!("unknown ICP setting in {line:?}"))?;
            one_round(&pairs, |(t, s)| black_box(icp::icp(t, s, config)).is_ok())?
        } else {
            let (_, f, q, fscratch, clouds) = networks
                .iter_mut()
                .find(|n| n.0 == what)
                .with_context(|| format!("unknown request {line:?}"))?;
            match setting {
                "f32" => one_round(clouds, |c| {
                    black_box(f.network_pose(black_box(c), 1, 0.0, fscratch)).is_ok()
                })?,
                "int8" => one_round(clouds, |c| {
                    black_box(q.network_pose(black_box(c), 1, 0.0)).is_ok()
                })?,
                _ => bail!("unknown precision in {line:?}"),
            }
        };
        writeln!(out, "{ms}")?;
        out.flush()?;
    }
    Ok(())
}

/// Every item through `call` once: wall-clock milliseconds per item.
fn one_round<T>(items: &[T], mut call: impl FnMut(&T) -> bool) -> anyhow::Result<f64> {
    let t = Instant::now();
    let ok = items.iter().filter(|c| call(c)).count();
    let per_call = t.elapsed().as_secs_f64() * 1e3 / items.len().max(1) as f64;
    if ok != items.len() {
        bail!(
            "{} of {} benchmark items failed",
            items.len() - ok,
            items.len()
        );
    }
    Ok(per_call)
}
