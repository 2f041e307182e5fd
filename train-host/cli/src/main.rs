//! `pcrnet`: the host command line (train, export, inspect, register,
//! track, pairs, eval, experiment, results, shape, untrained).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};

mod ambiguity;
mod device;
mod register;
mod scene;
mod track;
use pcrnet_core::{Arch, F32Model, Int8Model};
use pcrnet_eval::cli::MethodOptions;
use pcrnet_eval::methods::MethodKind;
use pcrnet_io::write::Coordinate;
use pcrnet_train::shapes::{Shape, random_transform, sample};
use pcrnet_train::template::{DEFAULT_TEMPLATE_POINTS, Reference};
use pcrnet_train::{
    CalibrationRule, EMBEDDED_ENCODER, EMBEDDED_HEAD, F32Params, TrainedFor, inspect, quantize,
};
use register::{Output, Reading, register};

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
        /// Print the int8 blob's sizes as C macros instead (a header for
        /// firmware: PCRNET_BLOB_SCRATCH_LEN, PCRNET_BLOB_LEN).
        #[arg(long, conflicts_with = "rust")]
        c_header: bool,
        /// Print the int8 blob's sizes as Rust consts instead (SCRATCH_LEN,
        /// BLOB_LEN; in Rust, pcrnet_core::scratch_len_for does the same at
        /// compile time).
        #[arg(long)]
        rust: bool,
    },
    /// Write the cloud IN into OUT in the format OUT's extension names
    /// (.pcd .ply .xyz .txt .csv .off, or .f32: raw little-endian f32 x y z
    /// triples, 12 bytes a point, no header, what firmware links). Points
    /// with a non-finite coordinate are left out, and the output says so.
    Convert {
        /// The cloud to read (.pcd .ply .off .xyz .txt .csv .f32).
        input: PathBuf,
        /// The file to write.
        output: PathBuf,
    },
    /// Run points -> quantize -> encode -> head -> pose end to end with
    /// seeded random (untrained) weights on a generated shape, int8 beside
    /// f32: the sizes and layers of an architecture before training it.
    /// (The trained model's demo is `cargo xtask demo`.)
    Untrained {
        /// Seed for weights, shape and transform.
        #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
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
    /// Train PCRNet / i-PCRNet / PointNetLK in f32 on ModelNet-style data
    /// or generated shapes; writes checkpoints, a JSON-lines log and, at
    /// the end, both blobs (f32 and int8, as `export`; none yet for
    /// PointNetLK) into --out.
    Train(Box<pcrnet_train::cli::TrainArgs>),
    /// Export a training checkpoint to the f32 and int8 blobs, with the
    /// template's feature embedded.
    Export(pcrnet_train::cli::ExportArgs),
    /// Upgrade a format-2 f32 blob to the current format (frame, template
    /// points, turns), writing f32 and re-quantized int8 blobs.
    Upgrade(pcrnet_train::cli::UpgradeArgs),
    /// Make a saved, seeded test set of pairs (from ModelNet-style folders,
    /// your own clouds, or generated shapes).
    Pairs(pcrnet_eval::cli::PairsArgs),
    /// Score a method on a saved pair set (rotation / translation errors,
    /// AUC, success ratios, time).
    Eval(pcrnet_eval::cli::EvalArgs),
    /// Run one of the paper's experiments (or `all`): trains missing
    /// models, scores every method, writes JSON and plots.
    Experiment(pcrnet_eval::cli::ExperimentArgs),
    /// Write RESULTS.md from the experiment reports.
    Results(pcrnet_eval::cli::ResultsArgs),
    /// Write a generated shape (centred, in the unit box) as XYZ text, and
    /// optionally a source made from it: the shape under a seeded random
    /// rigid transform (Euler U[-45, 45] deg, translation U[-1, 1]) as
    /// little-endian f32 x y z (the firmware example's input) and as XYZ.
    Shape {
        /// ell (no symmetry), box (half turns fit as well), torus, cylinder or
        /// cone (free about their axis).
        #[arg(long, default_value = "ell")]
        kind: String,
        /// Number of points.
        #[arg(long, default_value_t = 512, allow_negative_numbers = true)]
        points: usize,
        /// Seed of the sampling.
        #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
        seed: u64,
        /// Output XYZ file of the shape.
        #[arg(long)]
        out: PathBuf,
        /// Seed of the source's transform; with it, SOURCE.f32 and SOURCE.xyz
        /// are written next to --out.
        #[arg(long, allow_negative_numbers = true)]
        source_seed: Option<u64>,
    },
    /// Register SOURCE onto TEMPLATE (files: .pcd .ply .off .xyz .txt .csv
    /// .f32) and print the pose as quaternion + translation and as a 4x4
    /// matrix, with the residual and whether to trust it.
    ///
    /// Convention: p_template = R p_source + t (the template is the known
    /// object, the source what the sensor sees; Open3D's and PCL's
    /// registration_icp(source, target) name them source and target). The
    /// template comes first: swapping the two gives the inverse pose.
    /// Without TEMPLATE, the model's own template (stored in the blob) is
    /// used, exactly as on a device. Without --model, the shipped embedded
    /// default (built into pcrnet) is used, and the output says so.
    Register {
        /// `[TEMPLATE] SOURCE`: the template cloud (the known object;
        /// optional with a model) and the source cloud (what the sensor sees).
        /// Or name them with --template and --source.
        #[arg(
            num_args = 0..=2,
            value_name = "[TEMPLATE] SOURCE",
            required_unless_present = "source",
            conflicts_with_all = ["template", "source"]
        )]
        clouds: Vec<PathBuf>,
        /// The template cloud, named (in place of the positional TEMPLATE).
        #[arg(long, requires = "source")]
        template: Option<PathBuf>,
        /// The source cloud, named (in place of the positional SOURCE).
        #[arg(long)]
        source: Option<PathBuf>,
        /// Method: device (the firmware's pipeline: network, flip
        /// hypotheses, ICP against the template's points, residual), pcrnet
        /// (one pass), ipcrnet (iterative), pointnetlk (f32 blob) or icp.
        #[arg(long, value_enum, default_value_t = MethodKind::Device)]
        method: MethodKind,
        /// Model and settings of the method.
        #[command(flatten)]
        options: MethodOptions,
        /// Write the source moved onto the template here, in the format the
        /// extension names (.pcd and .ply binary, .xyz and .txt text, .off).
        #[arg(long)]
        aligned: Option<PathBuf>,
        /// Write the whole result as JSON to this file (`-`: standard output).
        #[arg(long)]
        json: Option<PathBuf>,
        /// SOURCE is a sensor frame holding the object among other things:
        /// a 16-bit depth PNG (with --intrinsics) or an organised PCD. The
        /// device's scene stages find the plane and the clusters of the
        /// object's size, and the best registered candidate wins
        /// (--method device only).
        #[arg(long)]
        scene: bool,
        /// With --scene and a depth PNG: the camera's intrinsics as JSON,
        /// {"fx", "fy", "cx", "cy" (pixels), "depth_scale" (user units per
        /// raw value: 0.001 reads millimetres as metres), "invalid" (optional)}.
        #[arg(long, requires = "scene")]
        intrinsics: Option<PathBuf>,
        /// With --scene: register at most this many of the largest clusters (1 to 8).
        #[arg(long, default_value_t = 3, requires = "scene")]
        candidates: usize,
        /// With --scene: the template's up axis (x, y, z, -x, -y or -z: the
        /// axis pointing away from the surface the object rests on;
        /// default: the blob's, when it was exported with --up). Each
        /// candidate is then registered by a sweep of turns about the
        /// plane found in the frame, for a view from one side in any yaw.
        #[arg(long, requires = "scene", allow_hyphen_values = true, value_parser = pcrnet_train::cli::parse_axis)]
        up: Option<[f32; 3]>,
        /// SOURCE is one object as a depth sensor saw it from X,Y,Z (the
        /// sensor's position in the source file's frame; 0,0,0 for points
        /// in the camera's own frame), everything else cut away: the
        /// device pipeline registers with that view (every start placed by
        /// what the sensor would see of the template there; of the turned
        /// starts, the lowest-residual one that explains it finishes) and its pose
        /// is reliable only if it also explains the view (the template's
        /// points it puts in view lie on the seen surface, none where the
        /// sensor saw past the object).
        #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = register::parse_point, conflicts_with = "scene")]
        viewpoint: Option<[f64; 3]>,
        /// How the clouds are read.
        #[command(flatten)]
        reading: Reading,
    },
    /// Follow the object of TEMPLATE through a sequence of frames: the
    /// first registered, each next one refined from the last pose.
    ///
    /// Convention: p_template = R p_source + t (the template is the known
    /// object, each frame a source: what the sensor sees); the template
    /// comes first. TEMPLATE is bound into the model (--template-points of
    /// it stored), both are read about its median, and poses are given in
    /// the files' frame. Frame 1 is registered with the device pipeline;
    /// each next frame takes one tracking step from the last pose (or, with
    /// --predict, its constant-velocity prediction): device ICP, kept when
    /// reliable and within a step, else a full registration in the same
    /// call (recovered, or lost: the next frame is tracked from the last
    /// reliable pose, its step falling back to a registration again).
    /// Without --model, the shipped embedded default int8 model (built into
    /// pcrnet) is used, and the output says so.
    Track(track::TrackArgs),
    /// Write a generated depth frame to try `register --scene` on: the
    /// model's template (the shipped one unless --model) standing on a
    /// table turned 200 degrees about its z axis beside two blocks, as a
    /// 224 x 172 time-of-flight camera sees it, the frame the QEMU harness
    /// runs. Writes OUT (16-bit PNG, millimetres) and OUT with .json
    /// (the intrinsics). Then: pcrnet register --scene OUT --intrinsics
    /// OUT.json --up z.
    Frame {
        /// The PNG to write; its intrinsics go beside it, extension .json.
        #[arg(long)]
        out: PathBuf,
        /// The int8 model whose template to draw (default: the shipped one).
        #[arg(long)]
        model: Option<PathBuf>,
    },
}

/// Errors print as one chain of messages (no backtrace, whatever
/// `RUST_BACKTRACE` says) and exit with status 1.
fn main() -> std::process::ExitCode {
    match run(Cli::parse().command) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Inspect {
            model,
            c_header,
            rust,
        } => {
            let blob =
                std::fs::read(&model).with_context(|| format!("reading {}", model.display()))?;
            let text = if c_header || rust {
                sizes_text(&model, &blob, c_header)?
            } else {
                inspect::describe(&blob).with_context(|| format!("{}", model.display()))?
            };
            write_stdout(&text);
        }
        Command::Convert { input, output } => {
            let cloud =
                pcrnet_io::read_cloud_local(&input, pcrnet_io::DEFAULT_MAX_POINTS, Some([0.0; 3]))?;
            if let Some(note) = cloud.left_out_note(&input) {
                eprintln!("{note}");
            }
            write_cloud(&output, &cloud.points)?;
            eprintln!(
                "wrote {} points of {} to {}",
                cloud.points.len(),
                input.display(),
                output.display()
            );
        }
        Command::Untrained {
            seed,
            out,
            encoder,
            head,
        } => {
            let arch = Arch::new(
                encoder.as_deref().unwrap_or(EMBEDDED_ENCODER),
                head.as_deref().unwrap_or(EMBEDDED_HEAD),
            )?;
            untrained(arch, seed, out)?
        }
        Command::Train(args) => pcrnet_train::cli::train(*args)?,
        Command::Export(args) => pcrnet_train::cli::export(args)?,
        Command::Upgrade(args) => pcrnet_train::cli::upgrade(args)?,
        Command::Pairs(args) => pcrnet_eval::cli::pairs(args)?,
        Command::Eval(args) => pcrnet_eval::cli::eval(args)?,
        Command::Experiment(args) => pcrnet_eval::cli::experiment(args)?,
        Command::Results(args) => pcrnet_eval::cli::results(args)?,
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
                "cylinder" => Shape::Cylinder,
                "cone" => Shape::Cone,
                other => anyhow::bail!("unknown shape {other} (box, torus, ell, cylinder, cone)"),
            };
            let cloud = sample(shape, points, seed);
            write_cloud(&out, &cloud)?;
            if let Some(s) = source_seed {
                let source = random_transform(&cloud, 45.0, 1.0, s);
                let bytes: Vec<u8> = source
                    .iter()
                    .flatten()
                    .flat_map(|v| v.to_le_bytes())
                    .collect();
                std::fs::write(out.with_extension("source.f32"), bytes)?;
                write_cloud(&out.with_extension("source.xyz"), &source)?;
            }
        }
        Command::Register {
            clouds,
            template,
            source,
            method,
            options,
            aligned,
            json,
            scene,
            intrinsics,
            candidates,
            up,
            viewpoint,
            reading,
        } => {
            reading.check()?;
            let (template, source) = match (clouds.as_slice(), &template, &source) {
                ([t, s], None, None) => (Some(t.as_path()), s.as_path()),
                ([s], None, None) => (None, s.as_path()),
                ([], t, Some(s)) => (t.as_deref(), s.as_path()),
                _ => anyhow::bail!(
                    "register takes [TEMPLATE] SOURCE, or --source FILE with an optional --template FILE"
                ),
            };
            if scene {
                anyhow::ensure!(
                    method == MethodKind::Device,
                    "--scene runs the device pipeline: leave out --method or give --method device"
                );
                let args = scene::SceneArgs {
                    template,
                    frame: source,
                    intrinsics: intrinsics.as_deref(),
                    candidates,
                    up,
                };
                return scene::run(args, &options, &reading, Output { aligned, json });
            }
            anyhow::ensure!(
                template.is_some() || options.template_points.is_none(),
                "--template-points applies to a TEMPLATE file bound in place of the blob's own; the blob's own template keeps the points it was exported with (`pcrnet export --template-points`, `pcrnet inspect` shows them)"
            );
            // Both clouds are read about the template's median; without a
            // template file the source stays in the blob's frame, exactly
            // as a device receives it.
            let template = template.map(|t| reading.load(t, None)).transpose()?;
            let origin = template.as_ref().map_or([0.0; 3], |t| t.origin);
            let source = reading.load(source, Some(origin))?.points;
            let template = template.map(|t| t.points);
            let out = Output { aligned, json };
            let seen = register::Seen { origin, viewpoint };
            register(template, &source, seen, method, &options, out)?
        }
        Command::Track(args) => track::track(args)?,
        Command::Frame { out, model } => scene::write_frame(&out, model.as_deref())?,
    }
    Ok(())
}

/// `pcrnet inspect MODEL --c-header` / `--rust`: the int8 blob's scratch
/// length at tile `MAX_TILE` (what `register` needs, from
/// `pcrnet_core::scratch_len_for`) and its length, for firmware to size
/// its buffers from.
fn sizes_text(path: &Path, blob: &[u8], c: bool) -> anyhow::Result<String> {
    let scratch = pcrnet_core::scratch_len_for(blob, pcrnet_core::MAX_TILE).with_context(|| {
        format!(
            "{}: not an int8 model blob (the sizes are for the device's int8 model; export one with pcrnet export)",
            path.display()
        )
    })?;
    let (name, len) = (path.display(), blob.len());
    Ok(if c {
        format!(
            "/* Generated by `pcrnet inspect {name} --c-header`: sizes of {name}. */\n\
             #define PCRNET_BLOB_SCRATCH_LEN {scratch}\n\
             #define PCRNET_BLOB_LEN {len}\n"
        )
    } else {
        format!(
            "// Generated by `pcrnet inspect {name} --rust`: sizes of {name}.\n\
             /// Scratch bytes `Int8Model::register` needs at tile `MAX_TILE`.\n\
             pub const SCRATCH_LEN: usize = {scratch};\n\
             /// Bytes of the blob.\n\
             pub const BLOB_LEN: usize = {len};\n"
        )
    })
}

/// `println!` through [`write_stdout`].
macro_rules! outln {
    ($($t:tt)*) => {
        write_stdout(&format!("{}\n", format_args!($($t)*)))
    };
}

/// Writes to standard output; a reader that has gone away (a closed pipe,
/// `| head -1`) ends the program quietly with status 0, as Unix tools do,
/// instead of a panic.
fn write_stdout(text: &str) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("error: writing to standard output: {e}");
        std::process::exit(1);
    }
}

/// Writes `cloud` in the format its extension names.
fn write_cloud<C: Coordinate>(path: &Path, cloud: &[[C; 3]]) -> anyhow::Result<()> {
    Ok(pcrnet_io::write::write_cloud(path, cloud)?)
}

/// Warns when `f32` cannot hold `cloud`'s shape: its coordinates are so
/// large against its extent that their spacing exceeds 1e-4 of it (map
/// coordinates in a blob's frame, with no template file to take a local
/// origin from).
fn warn_if_coarse(path: &Path, cloud: &[[f32; 3]]) {
    let (mut lo, mut hi, mut far) = ([f32::MAX; 3], [f32::MIN; 3], 0f32);
    for p in cloud {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
            far = far.max(p[k].abs());
        }
    }
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0f32, f32::max);
    let spacing = far * f32::EPSILON;
    // A cloud with no extent is degenerate, which the result reports: the
    // precision of its coordinates is not what is wrong with it.
    if extent > 0.0 && spacing > 1e-4 * extent {
        eprintln!(
            "warning: {}: coordinates reach {far:e} while the cloud spans {extent:e}; f32 keeps only {spacing:e} there. Give the template file too (both clouds are then read about a local origin), or express the cloud in the model's frame",
            path.display()
        );
    }
}

fn untrained(arch: Arch, seed: u64, out: Option<PathBuf>) -> anyhow::Result<()> {
    write_stdout(
        "NOTE: weights are seeded random (untrained): this shows the pipeline, not accuracy.
",
    );
    let params = F32Params::init(arch, seed);
    let template = sample(Shape::Ell, 1024, seed);
    let calibration: Vec<_> = (0..32)
        .map(|i| random_transform(&template, 45.0, 1.0, seed * 1000 + i))
        .collect();
    let reference = Reference::new(&template, DEFAULT_TEMPLATE_POINTS)?;
    // Like a trained default, the demo model centres its sources.
    let int8_blob = quantize(
        &params,
        &reference,
        &calibration,
        CalibrationRule::default(),
        TrainedFor::pcrnet(true),
    )?;
    let f32_blob = params.to_f32_blob(&reference, TrainedFor::pcrnet(true))?;
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
        outln!(
            "wrote demo-untrained-int8.pcrn, demo-untrained-f32.pcrn, demo-source.f32 to {}",
            dir.display()
        );
    }
    write_stdout(&inspect::describe(&int8_blob)?);

    let model = Int8Model::from_bytes(&int8_blob)?;
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let (pose, _) = model.network_pose(&source, 1, 0.0, &mut scratch)?;
    let fmodel = F32Model::from_bytes(&f32_blob)?;
    let mut fscratch = vec![0f32; fmodel.tiled_scratch_len()];
    let (fpose, _) = fmodel.network_pose(&source, 1, 0.0, &mut fscratch)?;
    outln!("source: {} points", source.len());
    outln!(
        "int8 pose: q = {:?}, t = {:?}",
        pose.rotation,
        pose.translation
    );
    outln!(
        "f32  pose: q = {:?}, t = {:?}",
        fpose.rotation,
        fpose.translation
    );
    for row in pose.matrix() {
        outln!(
            "  [{:>9.5} {:>9.5} {:>9.5} {:>9.5}]",
            row[0],
            row[1],
            row[2],
            row[3]
        );
    }
    Ok(())
}
