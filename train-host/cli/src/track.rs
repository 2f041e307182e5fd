//! `pcrnet track`: an object followed through a sequence of frames with
//! the device's tracking step (`Int8Model::track`), on the shipped model
//! unless told otherwise, with the template file bound in: one line per
//! frame (outcome, pose in the files' frame, residual, ICP iterations,
//! time), a summary, and the whole run as JSON.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use pcrnet_core::{Int8Model, Pose, Registration, TrackOutcome};
use pcrnet_eval::cli::MethodOptions;
use pcrnet_io::Format;
use pcrnet_io::frame::FilePose;

use crate::device::DeviceModel;
use crate::register::{Reading, json_on_stdout, say, write_json};
use pcrnet_eval::register::VIEW_SIDE;

/// The arguments of `pcrnet track`.
#[derive(clap::Args)]
pub(crate) struct TrackArgs {
    /// The template cloud: the known object (.pcd .ply .off .xyz .txt .csv
    /// .f32), bound into the model in place of its own.
    template: PathBuf,
    /// The frames in order: cloud files, or one folder (its cloud files,
    /// sorted by name).
    #[arg(required = true, value_name = "FRAME")]
    frames: Vec<PathBuf>,
    /// Start each tracking step from the constant-velocity prediction of
    /// the last two poses instead of the last pose (for an object moving
    /// fast and steadily).
    #[arg(long)]
    predict: bool,
    /// The frames are single views from a sensor standing at X,Y,Z (the
    /// files' frame; 0,0,0 for points in the camera's own frame): the
    /// registrations place their starts by what the sensor would see of
    /// the template and let the view choose among the turned starts
    /// (`Int8Model::register_view` until the first reliable pose,
    /// `track_view` after); the verdict is the residual's, as without it.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = crate::register::parse_point)]
    viewpoint: Option<[f64; 3]>,
    /// Model (an int8 blob) and settings of the device pipeline.
    #[command(flatten)]
    options: MethodOptions,
    /// Write every frame's result as JSON to this file (`-`: standard
    /// output; the lines for a person then go to standard error).
    #[arg(long)]
    json: Option<PathBuf>,
    /// How the clouds are read.
    #[command(flatten)]
    reading: Reading,
}

/// What was done with one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Registered afresh: frames until the first reliable pose.
    Registered,
    /// A tracking step from the last pose.
    Tracked(TrackOutcome),
}

impl Step {
    /// The word the JSON gives.
    fn name(self) -> &'static str {
        match self {
            Step::Registered => "registered",
            Step::Tracked(TrackOutcome::Kept) => "kept",
            Step::Tracked(TrackOutcome::Recovered) => "recovered",
            Step::Tracked(TrackOutcome::Lost) => "lost",
        }
    }
}

/// Frames per outcome, and their time.
#[derive(Debug, Default)]
struct Tally {
    frames: usize,
    registered: usize,
    kept: usize,
    recovered: usize,
    lost: usize,
    not_reliable: usize,
    ms: f64,
}

impl Tally {
    fn add(&mut self, step: Step, reliable: bool, ms: f64) {
        self.frames += 1;
        self.ms += ms;
        self.not_reliable += usize::from(!reliable);
        *match step {
            Step::Registered => &mut self.registered,
            Step::Tracked(TrackOutcome::Kept) => &mut self.kept,
            Step::Tracked(TrackOutcome::Recovered) => &mut self.recovered,
            Step::Tracked(TrackOutcome::Lost) => &mut self.lost,
        } += 1;
    }
}

/// Runs `pcrnet track`.
pub(crate) fn track(args: TrackArgs) -> anyhow::Result<()> {
    let TrackArgs {
        template,
        frames,
        predict,
        viewpoint,
        options,
        json,
        reading,
    } = args;
    // What is wrong with the flags and the files is said before any frame
    // is registered.
    options.check()?;
    reading.check()?;
    anyhow::ensure!(
        !options.refine_icp,
        "--refine-icp is register's host ICP after a network method; track runs the device pipeline, whose ICP --icp-iterations, --icp-distance and --icp-tolerance set"
    );
    check_file(&template, "the template")?;
    let frames = frame_files(&frames)?;
    let loaded = DeviceModel::load(&options, Some(&template), &reading, "track")?;
    let origin = loaded.origin;
    let model_label = loaded.label.clone();
    let model = Int8Model::from_bytes(&loaded.blob)
        .with_context(|| format!("{model_label} with {} bound in", template.display()))?;
    let device = loaded.options;
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let given_viewpoint = viewpoint;
    let viewpoint = viewpoint
        .map(|v| crate::register::local_viewpoint(v, origin))
        .transpose()?;
    let mut view = vec![0f32; pcrnet_core::scene::view::buffer_len(VIEW_SIDE)];

    let to_stdout = json_on_stdout(json.as_deref());
    let say = |line: String| say(to_stdout, &line);
    say(loaded.model_line());
    say(format!(
        "template: {} bound into the model ({} of its points stored for the check and ICP); local origin (its median; every frame is moved by it before rounding to f32): {origin:?}",
        template.display(),
        loaded.method.template_points.min(loaded.template_points),
    ));
    if let Some(line) = loaded.floor_line() {
        say(line);
    }
    say(format!(
        "{} frame(s); each step starts from {}; time: the registration or tracking call alone",
        frames.len(),
        if predict {
            "the constant-velocity prediction of the last two poses (the last pose after a fresh registration)"
        } else {
            "the last pose"
        }
    ));

    if let Some(at) = viewpoint {
        say(format!(
            "frames seen from {at:?} (about the local origin): registrations place their starts by what the sensor sees (register_view, track_view); the verdict is the residual's"
        ));
    }
    // The last two reliable poses while the track holds, the older first;
    // after a frame without one, the last reliable pose alone.
    let (mut before, mut last): (Option<Pose>, Option<Pose>) = (None, None);
    let mut tally = Tally::default();
    let mut results = Vec::with_capacity(frames.len());
    for (i, path) in frames.iter().enumerate() {
        let index = i + 1;
        // Reading errors name the file already.
        let source = reading
            .load(path, Some(origin))
            .with_context(|| format!("frame {index} of {}", frames.len()))?
            .points;
        let start = match (predict, before, last) {
            (true, Some(b), Some(l)) => Some(pcrnet_core::pose::predict(&b, &l).normalised()),
            (_, _, l) => l,
        };
        let began = Instant::now();
        let result = match (start, viewpoint) {
            (None, None) => model
                .register(&source, &device, &mut scratch)
                .map(|r| (r, Step::Registered)),
            (None, Some(at)) => model
                .register_view(&source, at, &device, &mut scratch, &mut view)
                .map(|v| (v.registration, Step::Registered)),
            (Some(previous), None) => model
                .track(&source, &previous, &device, &mut scratch)
                .map(|t| (t.registration, Step::Tracked(t.outcome))),
            (Some(previous), Some(at)) => model
                .track_view(&source, &previous, at, &device, &mut scratch, &mut view)
                .map(|t| (t.registration, Step::Tracked(t.outcome))),
        };
        let ms = began.elapsed().as_secs_f64() * 1e3;
        let (registration, step) = result
            .with_context(|| format!("frame {index} of {} ({})", frames.len(), path.display()))?;
        let reliable = registration.reliable;
        tally.add(step, reliable, ms);
        (before, last) = match (reliable, step) {
            (true, Step::Tracked(pcrnet_core::TrackOutcome::Kept)) => {
                (last, Some(registration.pose))
            }
            // A fresh pose: no velocity across it.
            (true, _) => (None, Some(registration.pose)),
            // Coast: the next frame is tracked from the last reliable pose
            // (the step falls back to a registration if it does not hold).
            (false, _) => (None, last),
        };
        let pose = FilePose::from_local(&registration.pose, origin);
        let name = path
            .file_name()
            .unwrap_or(path.as_os_str())
            .to_string_lossy();
        say(frame_line(index, &name, step, &registration, &pose, ms));
        results.push(frame_json(index, path, step, &registration, &pose, ms));
    }
    say(format!(
        "frames: {}, registered: {}, kept: {}, recovered: {}, lost: {}, not reliable: {}; mean {:.3} ms per frame",
        tally.frames,
        tally.registered,
        tally.kept,
        tally.recovered,
        tally.lost,
        tally.not_reliable,
        tally.ms / tally.frames.max(1) as f64
    ));
    if let Some(path) = json {
        let value = serde_json::json!({
            "model": model_label,
            "template": template.display().to_string(),
            "origin": origin,
            "template_floor": loaded.floor.map(crate::device::short),
            "verdict_max_residual": crate::device::short(device.max_residual),
            "predict": predict,
            "viewpoint": given_viewpoint,
            "frames": results,
        });
        write_json(&path, &value)?;
    }
    Ok(())
}

/// One frame for a person: index, file, outcome, pose in the files'
/// frame, relative plane residual, ICP iterations, time.
fn frame_line(
    index: usize,
    name: &str,
    step: Step,
    r: &Registration,
    pose: &FilePose,
    ms: f64,
) -> String {
    let outcome = match (step, r.reliable) {
        (Step::Registered, false) => "registered (not reliable)",
        _ => step.name(),
    };
    let [w, x, y, z] = r.pose.rotation;
    let [tx, ty, tz] = pose.translation;
    format!(
        "frame {index} {name}: {outcome}; q (w, x, y, z) [{w:.6}, {x:.6}, {y:.6}, {z:.6}]; t [{tx:.6}, {ty:.6}, {tz:.6}]; plane residual {:.4} of the size; {} ICP iteration(s); {ms:.3} ms",
        r.relative_plane_residual, r.icp_iterations,
    )
}

/// One frame as JSON: the pose in the files' frame (quaternion w, x, y, z,
/// translation, 4x4 row-major) and the check.
fn frame_json(
    index: usize,
    path: &Path,
    step: Step,
    r: &Registration,
    pose: &FilePose,
    ms: f64,
) -> serde_json::Value {
    serde_json::json!({
        "index": index,
        "file": path.display().to_string(),
        "outcome": step.name(),
        "quaternion_wxyz": r.pose.rotation,
        "translation": pose.translation,
        "matrix": pose.matrix(),
        "relative_plane_residual": r.relative_plane_residual,
        "fitness": r.fitness,
        "icp_iterations": r.icp_iterations,
        "passes": r.passes,
        "lk_iterations": r.lk_iterations,
        "reliable": r.reliable,
        "ms": ms,
    })
}

/// The frame files: those given, or one folder's cloud files sorted by
/// name. Each is checked (see [`check_file`]) before any is read.
fn frame_files(given: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let frames = match given {
        [folder] if folder.is_dir() => {
            let entries = std::fs::read_dir(folder)
                .with_context(|| format!("reading the folder {}", folder.display()))?;
            let mut files = Vec::new();
            for entry in entries {
                let path = entry
                    .with_context(|| format!("reading the folder {}", folder.display()))?
                    .path();
                if path.is_file() && Format::from_path(&path).is_some() {
                    files.push(path);
                }
            }
            anyhow::ensure!(
                !files.is_empty(),
                "{}: no cloud files in this folder (.pcd .ply .off .xyz .txt .csv .f32); give the frames as files, or a folder holding them",
                folder.display()
            );
            files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
            files
        }
        _ => {
            if let Some(folder) = given.iter().find(|p| p.is_dir()) {
                anyhow::bail!(
                    "{}: a folder among {} frames; give one folder alone (its cloud files are the frames, sorted by name), or the frame files",
                    folder.display(),
                    given.len()
                );
            }
            given.to_vec()
        }
    };
    for (i, path) in frames.iter().enumerate() {
        check_file(path, &format!("frame {}", i + 1))?;
    }
    Ok(frames)
}

/// Refuses `path` as `role` unless it is a non-empty file in a format
/// `pcrnet` reads, naming it and what to do.
fn check_file(path: &Path, role: &str) -> anyhow::Result<()> {
    let shown = path.display();
    let meta = match std::fs::metadata(path) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => anyhow::bail!(
            "{shown}: no such file ({role}); give the path of a cloud file (.pcd .ply .off .xyz .txt .csv .f32)"
        ),
        Err(e) => return Err(e).with_context(|| format!("{shown} ({role})")),
    };
    anyhow::ensure!(
        !meta.is_dir(),
        "{shown}: a folder ({role}); the template is one cloud file, and a folder of frames comes alone after it"
    );
    anyhow::ensure!(
        Format::from_path(path).is_some(),
        "{shown}: unknown point cloud format ({role}); expected extension .pcd, .ply, .off, .xyz, .txt, .csv or .f32"
    );
    anyhow::ensure!(
        meta.len() > 0,
        "{shown}: empty file ({role}); it holds no points: give a cloud file, or leave this one out"
    );
    Ok(())
}
