//! The `pcrnet export` and `pcrnet upgrade` subcommands: a checkpoint or a
//! format-2 blob, and a template file, to current f32 and int8 blobs.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use super::super::{Checkpoint, ModelKind, Sampling, data, export as exp};
use super::parse_sigma;
use crate::template::{DEFAULT_TEMPLATE_POINTS, Reference};

/// Arguments of `pcrnet export`.
#[derive(Debug, Clone, Args)]
pub struct ExportArgs {
    /// A checkpoint written by `pcrnet train`.
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// The template cloud (any format `pcrnet` reads).
    #[arg(long)]
    pub template: PathBuf,
    /// Points the template is reduced to (default: as in training,
    /// recorded in the checkpoint).
    #[arg(long, allow_negative_numbers = true)]
    pub points: Option<usize>,
    /// Template points stored in the blob for checking and refining poses
    /// on the device (about 10 bytes of flash each: 6 for the point, 3 for
    /// its normal, about 1 for the search grid).
    #[arg(long, default_value_t = DEFAULT_TEMPLATE_POINTS, allow_negative_numbers = true)]
    pub template_points: usize,
    /// Add PointNetLK's solver for the template to both blobs, so that
    /// `Options::lk_iterations` can refine a pose in feature space (about
    /// 24 bytes of flash per feature entry: 6 KB at F = 256). Always there
    /// for a model trained as PointNetLK.
    #[arg(long)]
    pub lk: bool,
    /// The template's up axis, stored in both blobs (see `train --up`; a
    /// checkpoint does not keep the one `train` was given: give it again).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_axis)]
    pub up: Option<[f32; 3]>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
}

/// Parses an up axis (`--up`): `x`, `y`, `z`, `-x`, `-y` or `-z`.
pub fn parse_axis(s: &str) -> Result<[f32; 3], String> {
    let axis = match s.trim().to_ascii_lowercase().as_str() {
        "x" | "+x" => [1.0, 0.0, 0.0],
        "y" | "+y" => [0.0, 1.0, 0.0],
        "z" | "+z" => [0.0, 0.0, 1.0],
        "-x" => [-1.0, 0.0, 0.0],
        "-y" => [0.0, -1.0, 0.0],
        "-z" => [0.0, 0.0, -1.0],
        other => {
            return Err(format!(
                "`{other}` is not an axis: give x, y, z, -x, -y or -z (the template's axis pointing away from the surface it rests on)"
            ));
        }
    };
    Ok(axis)
}

/// `reference` with the up axis `up` recorded, if given.
pub(super) fn with_up(mut reference: Reference, up: Option<[f32; 3]>) -> anyhow::Result<Reference> {
    if let Some(up) = up {
        reference.set_up(up)?;
    }
    Ok(reference)
}

/// Reads a template file, reduces it as the training shapes were (farthest
/// points), and records it for a blob: frame, stored points, turns. The
/// template keeps its own units and axes.
pub(super) fn load_template(
    path: &Path,
    points: usize,
    stored: usize,
    seed: u64,
) -> anyhow::Result<Reference> {
    let raw = pcrnet_io::read_cloud(path)?;
    let reduced = data::reduce(&raw, points, Sampling::Fps, seed)
        .with_context(|| format!("{}: no finite point", path.display()))?;
    let mut reference =
        Reference::new(&reduced, stored).with_context(|| format!("{}", path.display()))?;
    // The floor on the whole file: the reduced cloud's other points are
    // farthest-point picks too, the nearest to the stored ones.
    let finite: Vec<[f32; 3]> = raw
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .copied()
        .collect();
    reference
        .measure_floor(&finite)
        .with_context(|| format!("{}", path.display()))?;
    Ok(reference)
}

/// Arguments of `pcrnet upgrade`.
#[derive(Debug, Clone, Args)]
pub struct UpgradeArgs {
    /// A format-3 blob of either kind (the closest-point table is added:
    /// model-int8.pcrn or model-f32.pcrn in --out), or a format-2 f32 blob
    /// (it holds all the weights: both blobs are exported afresh).
    #[arg(long)]
    pub model: PathBuf,
    /// The template cloud to record (any format `pcrnet` reads, any units):
    /// needed for a format-2 blob only.
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// Points the template is reduced to, as in training.
    #[arg(long, default_value_t = 512, allow_negative_numbers = true)]
    pub points: usize,
    /// Template points stored in the blob (about 10 bytes of flash each: 6
    /// for the point, 3 for its normal, about 1 for the search grid).
    #[arg(long, default_value_t = DEFAULT_TEMPLATE_POINTS, allow_negative_numbers = true)]
    pub template_points: usize,
    /// Gaussian noise on the calibration sources: a fixed SIGMA or a range
    /// LO,HI, as `train --noise` (0 for clean sources).
    #[arg(long, default_value = "0,0.04")]
    pub noise: String,
    /// Seed of the template reduction and the calibration clouds.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// Network passes the model was trained for (format 2 did not record
    /// it): 1 for PCRNet, the training's `--iterations` for i-PCRNet.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..), allow_negative_numbers = true)]
    pub passes: u16,
    /// Output folder (model-f32.pcrn, model-int8.pcrn).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `pcrnet upgrade`: a format-3 blob gains its closest-point table; a
/// format-2 f32 blob becomes current f32 and int8 blobs.
pub fn upgrade(args: UpgradeArgs) -> anyhow::Result<()> {
    let noise = parse_sigma(&args.noise, "--noise")?;
    let blob =
        std::fs::read(&args.model).with_context(|| format!("reading {}", args.model.display()))?;
    let version = blob.get(4..6).map(|v| u16::from_le_bytes([v[0], v[1]]));
    if version.is_some_and(|v| (3..=pcrnet_core::format::FORMAT_VERSION).contains(&v)) {
        let (kind, out) = crate::upgrade::add_table(&blob)
            .with_context(|| format!("{}", args.model.display()))?;
        let name = match kind {
            pcrnet_core::format::ModelKind::Int8 => "model-int8.pcrn",
            pcrnet_core::format::ModelKind::F32 => "model-f32.pcrn",
        };
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?;
        let path = args.out.join(name);
        std::fs::write(&path, out).with_context(|| format!("writing {}", path.display()))?;
        println!(
            "wrote {} (format {})",
            path.display(),
            pcrnet_core::format::FORMAT_VERSION
        );
        return Ok(());
    }
    let (params, centre) =
        crate::upgrade::read_v2_f32(&blob).with_context(|| format!("{}", args.model.display()))?;
    let template = args.template.as_ref().ok_or_else(|| {
        anyhow::anyhow!(
            "{}: a format-2 blob needs --template (the cloud to record as its template)",
            args.model.display()
        )
    })?;
    let reference = load_template(template, args.points, args.template_points, args.seed)?;
    let pairs = data::PairConfig {
        noise: (noise[1] > 0.0).then_some(noise),
        centre,
        ..data::PairConfig::default()
    };
    let trained = crate::TrainedFor {
        passes: args.passes,
        ..crate::TrainedFor::pcrnet(centre)
    };
    write_blobs(&params, &reference, &pairs, args.seed, trained, &args.out)
}

/// How a training configuration's network should be run: centred
/// sources as its pairs were, i-PCRNet's passes, PointNetLK's iterations
/// (and no head), and whether the blobs carry PointNetLK's solver.
pub(super) fn trained_for(config: &super::TrainConfig, lk_solver: bool) -> crate::TrainedFor {
    let centre = config.pairs.centre;
    let count = |n: usize| u16::try_from(n).unwrap_or(u16::MAX);
    match config.model {
        ModelKind::Pcrnet => crate::TrainedFor {
            lk_solver,
            ..crate::TrainedFor::pcrnet(centre)
        },
        ModelKind::Ipcrnet { iterations } => crate::TrainedFor {
            passes: count(iterations),
            lk_solver,
            ..crate::TrainedFor::pcrnet(centre)
        },
        ModelKind::PointNetLk { iterations } => {
            crate::TrainedFor::pointnetlk(centre, count(iterations))
        }
    }
}

/// Runs `pcrnet export`.
pub fn export(args: ExportArgs) -> anyhow::Result<()> {
    let ck = Checkpoint::load(&args.checkpoint)?;
    let trained = trained_for(&ck.config, args.lk);
    let points = args.points.unwrap_or(ck.config.points);
    let reference = with_up(
        load_template(&args.template, points, args.template_points, ck.config.seed)?,
        args.up,
    )?;
    write_blobs(
        &ck.params(),
        &reference,
        &ck.config.pairs,
        ck.config.seed,
        trained,
        &args.out,
    )
}

/// Calibration sources made from the template as `pairs` makes sources
/// (seeded), then both blobs of `params` with `reference` as their
/// template written to `out`, each path printed: what `train`, `export`
/// and `upgrade` end with.
pub(super) fn write_blobs(
    params: &crate::F32Params,
    reference: &Reference,
    pairs: &data::PairConfig,
    seed: u64,
    trained: crate::TrainedFor,
    out: &Path,
) -> anyhow::Result<()> {
    let cal = exp::calibration_clouds(&reference.normalised(), pairs, CALIBRATION_CLOUDS, seed);
    for p in exp::export(params, reference, Some(&cal), trained, out)? {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// Calibration sources per quantization.
const CALIBRATION_CLOUDS: usize = 64;
