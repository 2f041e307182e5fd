//! `pcrnet`: the host command line (train, export, inspect, register,
//! pairs, eval, experiment, results, shape, demo).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};
use pcrnet_core::{Arch, F32Model, Int8Model, MAX_TILE};
use pcrnet_train::eval::cli::MethodOptions;
use pcrnet_train::eval::methods::{self, MethodKind};
use pcrnet_train::shapes::{Shape, random_transform, sample};
use pcrnet_train::{
    CalibrationRule, EMBEDDED_ENCODER, EMBEDDED_HEAD, F32Params, inspect, quantize,
};

#[derive(Parser)]
#[command(
    name = "pcrnet",
    version,
    about = "PCRNet point cloud registration: host tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print a model blob's layers, parameters, quantization, flash and RAM.
    Inspect {
        /// The blob (int8 or f32).
        model: PathBuf,
    },
    /// Run points -> quantize -> encode -> head -> pose end to end on a
    /// generated shape, int8 beside f32, with the embedded default architecture.
    Demo {
        /// Seed for weights, shape and transform.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Write the int8 and f32 blobs into this folder.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Encoder widths (default: the embedded default).
        #[arg(long, value_delimiter = ',')]
        encoder: Option<Vec<u16>>,
        /// Hidden head widths (default: the embedded default).
        #[arg(long, value_delimiter = ',')]
        head: Option<Vec<u16>>,
    },
    /// Train PCRNet / i-PCRNet in f32 on ModelNet-style data or generated
    /// shapes; writes checkpoints, a JSON-lines log and the f32 blob (and
    /// with --export the int8 blob) into --out.
    Train(Box<pcrnet_train::train::cli::TrainArgs>),
    /// Export a training checkpoint to the f32 and int8 blobs, with the
    /// template's feature embedded.
    Export(pcrnet_train::train::cli::ExportArgs),
    /// Make a saved, seeded test set of pairs (from ModelNet-style folders,
    /// your own clouds, or generated shapes).
    Pairs(pcrnet_train::eval::cli::PairsArgs),
    /// Score a method on a saved pair set (rotation / translation errors,
    /// AUC, success ratios, time).
    Eval(pcrnet_train::eval::cli::EvalArgs),
    /// Run one of the paper's experiments (or `all`): trains missing
    /// models, scores every method, writes JSON and plots.
    Experiment(pcrnet_train::eval::cli::ExperimentArgs),
    /// Write RESULTS.md from the experiment reports.
    Results(pcrnet_train::eval::cli::ResultsArgs),
    /// Write a generated shape (centred, in the unit box) as XYZ text, and
    /// optionally a source made from it: the shape under a seeded random
    /// rigid transform (Euler U[-45, 45] deg, translation U[-1, 1]) as
    /// little-endian f32 x y z (the firmware example's input) and as XYZ.
    Shape {
        /// box, torus or ell.
        #[arg(long, default_value = "ell")]
        kind: String,
        /// Number of points.
        #[arg(long, default_value_t = 512)]
        points: usize,
        /// Seed of the sampling.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output XYZ file of the shape.
        #[arg(long)]
        out: PathBuf,
        /// Seed of the source's transform; with it, SOURCE.f32 and SOURCE.xyz
        /// are written next to --out.
        #[arg(long)]
        source_seed: Option<u64>,
    },
    /// Register SOURCE onto TEMPLATE (files: .pcd .ply .off .xyz .txt) and
    /// print the pose as quaternion + translation and as a 4x4 matrix.
    Register {
        /// The template cloud (the known model).
        template: PathBuf,
        /// The source cloud (what the sensor sees).
        source: PathBuf,
        /// Method: pcrnet (one pass), ipcrnet (iterative), pointnetlk (f32 blob) or icp.
        #[arg(long, value_enum, default_value_t = MethodKind::Pcrnet)]
        method: MethodKind,
        /// Model and settings of the method.
        #[command(flatten)]
        options: MethodOptions,
        /// Write the source moved onto the template here (XYZ text).
        #[arg(long)]
        aligned: Option<PathBuf>,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Inspect { model } => {
            let blob =
                std::fs::read(&model).with_context(|| format!("reading {}", model.display()))?;
            let text = inspect::describe(&blob).with_context(|| format!("{}", model.display()))?;
            print!("{text}");
        }
        Command::Demo {
            seed,
            out,
            encoder,
            head,
        } => {
            let arch = Arch::new(
                encoder.as_deref().unwrap_or(EMBEDDED_ENCODER),
                head.as_deref().unwrap_or(EMBEDDED_HEAD),
            )?;
            demo(arch, seed, out)?
        }
        Command::Train(args) => pcrnet_train::train::cli::train(*args)?,
        Command::Export(args) => pcrnet_train::train::cli::export(args)?,
        Command::Pairs(args) => pcrnet_train::eval::cli::pairs(args)?,
        Command::Eval(args) => pcrnet_train::eval::cli::eval(args)?,
        Command::Experiment(args) => pcrnet_train::eval::cli::experiment(args)?,
        Command::Results(args) => pcrnet_train::eval::cli::results(args)?,
        Command::Shape {
            kind,
            points,
            seed,
            out,
            source_seed,
        } => {
            let shape = match kind.as_str() {
                "box" => Shape::Box,
                "torus" => Shape::Torus,
                "ell" => Shape::Ell,
                other => anyhow::bail!("unknown shape {other} (box, torus, ell)"),
            };
            let cloud = sample(shape, points, seed);
            write_xyz(&out, &cloud)?;
            if let Some(s) = source_seed {
                let source = random_transform(&cloud, 45.0, 1.0, s);
                let bytes: Vec<u8> = source
                    .iter()
                    .flatten()
                    .flat_map(|v| v.to_le_bytes())
                    .collect();
                std::fs::write(out.with_extension("source.f32"), bytes)?;
                write_xyz(&out.with_extension("source.xyz"), &source)?;
            }
        }
        Command::Register {
            template,
            source,
            method,
            options,
            aligned,
        } => register(&template, &source, method, &options, aligned)?,
    }
    Ok(())
}

fn register(
    template_path: &Path,
    source_path: &Path,
    kind: MethodKind,
    options: &MethodOptions,
    aligned: Option<PathBuf>,
) -> anyhow::Result<()> {
    let template = read_cloud(template_path)?;
    let source = read_cloud(source_path)?;
    let method = options.method(kind);
    let blob = options.read_model()?;
    let out =
        methods::run(&method, blob.as_deref(), &template, &source).with_context(
            || match &options.model {
                Some(path) => format!("registering with {}", path.display()),
                None => "registering".into(),
            },
        )?;
    let pose = out.pose;
    println!(
        "method: {}, {} step(s)",
        method.name(out.precision),
        out.iterations
    );
    println!("time: {:.3} ms", out.seconds * 1e3);
    println!("quaternion (w, x, y, z): {:?}", pose.rotation);
    println!("translation: {:?}", pose.translation);
    println!("matrix (maps source onto template):");
    for row in pose.matrix() {
        println!(
            "  [{:>10.6} {:>10.6} {:>10.6} {:>10.6}]",
            row[0], row[1], row[2], row[3]
        );
    }
    if let Some(out) = aligned {
        let moved: Vec<[f32; 3]> = source.iter().map(|&p| pose.transform_point(p)).collect();
        write_xyz(&out, &moved)?;
        println!("aligned source written to {}", out.display());
    }
    Ok(())
}

/// Writes a cloud as XYZ text (one `x y z` line per point, exact f32 values).
fn write_xyz(path: &Path, cloud: &[[f32; 3]]) -> anyhow::Result<()> {
    let text: String = cloud
        .iter()
        .map(|p| format!("{:?} {:?} {:?}\n", p[0], p[1], p[2]))
        .collect();
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn read_cloud(path: &Path) -> anyhow::Result<Vec<[f32; 3]>> {
    let cloud = pcrnet_train::io::read_cloud(path)?;
    anyhow::ensure!(!cloud.is_empty(), "{}: no points", path.display());
    Ok(cloud)
}

fn demo(arch: Arch, seed: u64, out: Option<PathBuf>) -> anyhow::Result<()> {
    println!("NOTE: weights are seeded random (untrained): this shows the pipeline, not accuracy.");
    let params = F32Params::init(arch, seed);
    let template = sample(Shape::Ell, 1024, seed);
    let calibration: Vec<_> = (0..32)
        .map(|i| random_transform(&template, 45.0, 1.0, seed * 1000 + i))
        .collect();
    // Like a trained default, the demo model centres its sources.
    let int8_blob = quantize(
        &params,
        &template,
        &calibration,
        CalibrationRule::default(),
        true,
    )?;
    let f32_blob = params.to_f32_blob(&template, true)?;
    let source = random_transform(&template, 45.0, 1.0, seed.wrapping_add(77));
    if let Some(dir) = out {
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join("demo-untrained-int8.pcrn"), &int8_blob)?;
        std::fs::write(dir.join("demo-untrained-f32.pcrn"), &f32_blob)?;
        let bytes: Vec<u8> = source
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        std::fs::write(dir.join("demo-source.f32"), bytes)?;
        println!(
            "wrote demo-untrained-int8.pcrn, demo-untrained-f32.pcrn, demo-source.f32 to {}",
            dir.display()
        );
    }
    print!("{}", inspect::describe(&int8_blob)?);

    let model = Int8Model::from_bytes(&int8_blob)?;
    let mut scratch = vec![0i8; model.scratch_len(MAX_TILE)];
    let pose = model.register(&source, &mut scratch)?;
    let fmodel = F32Model::from_bytes(&f32_blob)?;
    let mut fscratch = vec![0f32; fmodel.scratch_len()];
    let fpose = fmodel.register(&source, &mut fscratch)?;
    println!("source: {} points", source.len());
    println!(
        "int8 pose: q = {:?}, t = {:?}",
        pose.rotation, pose.translation
    );
    println!(
        "f32  pose: q = {:?}, t = {:?}",
        fpose.rotation, fpose.translation
    );
    for row in pose.matrix() {
        println!(
            "  [{:>9.5} {:>9.5} {:>9.5} {:>9.5}]",
            row[0], row[1], row[2], row[3]
        );
    }
    Ok(())
}
