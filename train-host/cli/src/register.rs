//! `pcrnet register`: one registration of the source onto the template
//! with any method, on the shipped model unless told otherwise, printed
//! for a person (pose, matrix, residual, verdict) and as JSON. The pieces
//! `pcrnet track` shares with it: the shipped model, how clouds are read
//! ([`Reading`]), and where lines and JSON go ([`say`], [`write_json`]).

use std::path::{Path, PathBuf};

use anyhow::Context;
use pcrnet_eval::cli::MethodOptions;
use pcrnet_eval::methods::{self, MethodKind};
use pcrnet_io::frame::FilePose;
use pcrnet_io::progress::Progress;
use pcrnet_io::reduce::{Reduction, reduce_cloud};
use pcrnet_io::{LocalCloud, read_cloud_local};

use crate::{warn_if_coarse, write_cloud, write_stdout};

/// How cloud files are read: the size limit and the reduction of large
/// clouds (the flags `register` and `track` share).
#[derive(clap::Args)]
pub(crate) struct Reading {
    /// Refuse cloud files that declare or hold more points than this
    /// (before allocating: a small hostile file can declare billions).
    #[arg(long, default_value_t = pcrnet_io::DEFAULT_MAX_POINTS, allow_negative_numbers = true)]
    max_cloud_points: usize,
    /// Keep at most this many points of each cloud (0: all): a large
    /// scan registers as well from a few thousand, much faster.
    #[arg(long, default_value_t = pcrnet_io::reduce::DEFAULT_SOURCE_POINTS, allow_negative_numbers = true)]
    reduce_to: usize,
    /// How to keep them: random (seeded; keeps the density), fps
    /// (farthest points: even coverage, slow on millions), voxel (the
    /// mean per cube of --voxel units, then random).
    #[arg(long, value_enum, default_value_t = Reduction::Random)]
    reduce: Reduction,
    /// Cube side for --reduce voxel, in the clouds' units.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    voxel: f32,
}

impl Reading {
    /// The most points a cloud file may hold.
    pub(crate) fn max_cloud_points(&self) -> usize {
        self.max_cloud_points
    }

    /// Refuses `--reduce voxel` without a cube side.
    pub(crate) fn check(&self) -> anyhow::Result<()> {
        if self.reduce == Reduction::Voxel && !(self.voxel.is_finite() && self.voxel > 0.0) {
            anyhow::bail!(
                "--reduce voxel needs --voxel SIZE: the cube side in the clouds' units, e.g. a tenth of the object's size"
            );
        }
        Ok(())
    }

    /// Reads `path` in f64 and moves it by `origin` (`None`: its own
    /// median, as for a template file) before rounding to f32, so map
    /// coordinates keep their shape; then reduces it as the flags say. A
    /// cloud with no finite point is an error naming the file.
    pub(crate) fn load(&self, path: &Path, origin: Option<[f64; 3]>) -> anyhow::Result<LocalCloud> {
        let Reading {
            max_cloud_points,
            reduce_to,
            reduce,
            voxel,
        } = *self;
        let reading = Progress::spinner(format!("reading {}", path.display()));
        let mut cloud = read_cloud_local(path, max_cloud_points, origin)?;
        drop(reading);
        anyhow::ensure!(
            !cloud.points.is_empty(),
            "{}: no point with three finite coordinates ({} read)",
            path.display(),
            cloud.left_out
        );
        if let Some(note) = cloud.left_out_note(path) {
            eprintln!("{note}");
        }
        warn_if_coarse(path, &cloud.points);
        let kept = reduce_cloud(&cloud.points, reduce, reduce_to, voxel, 0);
        if kept.len() < cloud.points.len() {
            eprintln!(
                "{}: {} points, {} kept ({reduce:?}; --reduce-to {reduce_to}, 0 keeps all)",
                path.display(),
                cloud.points.len(),
                kept.len()
            );
        }
        anyhow::ensure!(!kept.is_empty(), "{}: no finite point", path.display());
        cloud.points = kept;
        Ok(cloud)
    }
}

/// Whether `--json` sends the JSON to standard output (`-`): the lines for
/// a person then go to standard error, so that it carries the JSON alone.
pub(crate) fn json_on_stdout(json: Option<&Path>) -> bool {
    json == Some(Path::new("-"))
}

/// Prints a line for a person: on standard output, or on standard error
/// when standard output carries the JSON (see [`json_on_stdout`]).
pub(crate) fn say(json_on_stdout: bool, line: &str) {
    if json_on_stdout {
        eprintln!("{line}");
    } else {
        write_stdout(&format!("{line}\n"));
    }
}

/// Writes `value` as pretty JSON to `path` (`-`: standard output).
pub(crate) fn write_json(path: &Path, value: &serde_json::Value) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value)? + "\n";
    if json_on_stdout(Some(path)) {
        write_stdout(&text);
    } else {
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Where `register` writes besides standard output.
pub(crate) struct Output {
    /// The source moved onto the template (format by extension).
    pub(crate) aligned: Option<PathBuf>,
    /// The result as JSON (`-`: standard output).
    pub(crate) json: Option<PathBuf>,
}

/// The shipped embedded default (`models/`), built into the binary so that
/// `pcrnet register TEMPLATE SOURCE` runs anywhere without `--model`: the
/// int8 blob for the network methods, the f32 blob for PointNetLK (which
/// needs f32 features), none for ICP. With its file name, to say which.
pub(crate) fn shipped_model(kind: MethodKind) -> Option<(&'static [u8], &'static str)> {
    match kind {
        MethodKind::Icp => None,
        MethodKind::Pointnetlk => Some((
            include_bytes!("../../../models/embedded-default-f32.pcrn"),
            "models/embedded-default-f32.pcrn",
        )),
        MethodKind::Pcrnet | MethodKind::Ipcrnet | MethodKind::Device => Some((
            include_bytes!("../../../models/embedded-default-int8.pcrn"),
            "models/embedded-default-int8.pcrn",
        )),
    }
}

/// Where the clouds of [`register`] lie and were seen from.
pub(crate) struct Seen {
    /// Both clouds were moved by this (the files' frame) before rounding to f32.
    pub origin: [f64; 3],
    /// `--viewpoint`: the sensor's position, the files' frame.
    pub viewpoint: Option<[f64; 3]>,
}

/// `--viewpoint` (the files' frame) in the clouds' local frame, as the
/// points were moved by `origin`; refused when f32 cannot hold it.
pub(crate) fn local_viewpoint(v: [f64; 3], origin: [f64; 3]) -> anyhow::Result<[f32; 3]> {
    let local = [0, 1, 2].map(|k| (v[k] - origin[k]) as f32);
    anyhow::ensure!(
        local.iter().all(|c| c.is_finite()),
        "--viewpoint lies too far from the clouds for f32 (is it in the files' frame?)"
    );
    Ok(local)
}

/// Parses `X,Y,Z` (finite numbers).
pub(crate) fn parse_point(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}; give three numbers X,Y,Z"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("`{s}`: give three finite numbers X,Y,Z")),
    }
}

/// Registers `source` onto `template` (the blob's own when `None`), both
/// given about `seen.origin` in the files' frame, and reports the pose in the
/// files' frame.
pub(crate) fn register(
    template: Option<Vec<[f32; 3]>>,
    source: &[[f32; 3]],
    seen: Seen,
    kind: MethodKind,
    options: &MethodOptions,
    Output { aligned, json }: Output,
) -> anyhow::Result<()> {
    options.check()?;
    let origin = seen.origin;
    anyhow::ensure!(
        seen.viewpoint.is_none() || kind == MethodKind::Device,
        "--viewpoint checks the device pipeline's pose against the view: leave out --method or give --method device"
    );
    anyhow::ensure!(
        seen.viewpoint.is_none() || !options.refine_icp,
        "--viewpoint checks the device pipeline's own pose, which --refine-icp would move: leave out one of them"
    );
    let viewpoint = seen
        .viewpoint
        .map(|v| local_viewpoint(v, origin))
        .transpose()?;
    let mut method = options.method(kind);
    method.view_check = viewpoint.is_some();
    let (blob, model_note) = match options.read_model()? {
        Some(blob) => (Some(blob), None),
        None => match shipped_model(kind) {
            Some((blob, name)) => (
                Some(blob.to_vec()),
                Some(format!(
                    "model: the shipped embedded default ({name}, built into pcrnet; --model FILE to use another)"
                )),
            ),
            None => (None, None),
        },
    };
    options.check_hypotheses(kind, blob.as_deref(), template.is_some())?;
    if let Some(warning) = options.mode_warning(kind, blob.as_deref()) {
        eprintln!("warning: {warning}");
    }
    // The device pipeline's verdict: calibrated by the template's residual
    // floor (the one binding stores, or the blob's) unless --max-residual
    // is given, as `track` and `--scene` do.
    let floor = match (kind, &blob) {
        (MethodKind::Device, Some(blob)) => {
            crate::device::device_floor(blob, template.as_deref(), method.template_points)
        }
        _ => None,
    };
    method.max_residual = crate::device::verdict(options, floor, method.max_residual);
    let registering = Progress::spinner(format!("registering with {}", method.name(None)));
    let out = methods::run(
        &method,
        blob.as_deref(),
        template.as_deref(),
        source,
        viewpoint,
    );
    drop(registering);
    let out = out.with_context(|| match &options.model {
        Some(path) => format!("registering with {}", path.display()),
        None => "registering".into(),
    })?;
    let pose = FilePose::from_local(&out.pose, origin);
    let to_stdout = json_on_stdout(json.as_deref());
    let say = |line: String| say(to_stdout, &line);
    say(format!(
        "method: {}, {} pass(es)/step(s){}",
        method.name(out.precision),
        out.iterations,
        match (kind, &template) {
            (MethodKind::Device, None) => " - the firmware's pipeline, the blob's own template",
            (MethodKind::Device, Some(_)) =>
                " - the firmware's pipeline, with the given template bound into the model",
            _ => "",
        }
    ));
    if let Some(note) = model_note {
        say(note);
    }
    if let Some(line) = crate::device::floor_line(floor, method.max_residual) {
        say(line);
    }
    say(format!("time: {:.3} ms", out.seconds * 1e3));
    say(format!("quaternion (w, x, y, z): {:?}", out.pose.rotation));
    if origin == [0.0; 3] {
        // The f32 values a device gives.
        say(format!("translation: {:?}", out.pose.translation));
    } else {
        say(format!("translation: {:?}", pose.translation));
        say(format!(
            "local origin (the median of the template file's points, or of an OFF mesh's vertices; both clouds were moved by it before rounding to f32): {origin:?}; translation about it: {:?}",
            pose.local_translation
        ));
    }
    say("matrix (maps source onto template, in the files' frame):".into());
    for row in pose.matrix() {
        say(format!(
            "  [{:>10.6} {:>10.6} {:>10.6} {:>10.6}]",
            row[0], row[1], row[2], row[3]
        ));
    }
    if let (None, Some(d)) = (&out.check, out.degenerate) {
        say(format!(
            "degenerate source: {d:?} - its points do not determine a rotation; do not act on this pose"
        ));
    }
    if let Some(c) = &out.check {
        say(format!(
            "residual: {:.6} (source units), {:.4} of the template's size; plane residual {:.6}, {:.4} of the size; fitness {:.3}; inlier RMSE {:.6}",
            c.residual,
            c.relative_residual,
            c.plane_residual,
            c.relative_plane_residual,
            c.fitness,
            c.inlier_rmse
        ));
        say(format!(
            "hypothesis {} won; {} network pass(es), {} PointNetLK step(s), {} ICP iteration(s); {} saturated int8 value(s){}",
            c.hypothesis,
            c.passes,
            c.lk_iterations,
            c.icp_iterations,
            c.saturated,
            match c.degenerate {
                Some(d) => format!("; degenerate source: {d:?}"),
                None => String::new(),
            }
        ));
        if c.saturated > 0 {
            say(format!(
                "{} int8 value(s) clipped at the top of their range: the cloud is larger than the model was calibrated for (another scale or object?); the int8 pose can differ from the f32 model's",
                c.saturated
            ));
        }
        if c.out_of_range > 0 {
            say(format!(
                "{} point(s) outside the model's input range were left out of the network and the centring (stray points far from the object)",
                c.out_of_range
            ));
        }
        for line in crate::ambiguity::lines(&c.ambiguity, origin) {
            say(line);
        }
        if let Some(v) = &out.view {
            say(format!(
                "view check from the viewpoint: {} template point(s) on the seen surface, {} where the sensor saw past the object, {} behind the seen surface: {}",
                v.supported,
                v.violations,
                v.occluded,
                if v.passed { "passed" } else { "FAILED" }
            ));
        }
        say(trust_line(c.reliable, out.view.map(|v| v.passed)));
    }
    if let Some(out_path) = aligned {
        if origin == [0.0; 3] {
            // In f32, exactly as a device moves the points.
            let moved: Vec<[f32; 3]> = source
                .iter()
                .map(|&p| out.pose.transform_point(p))
                .collect();
            write_cloud(&out_path, &moved)?;
        } else {
            let moved: Vec<[f64; 3]> = source
                .iter()
                .map(|p| pose.transform_point([0, 1, 2].map(|k| origin[k] + f64::from(p[k]))))
                .collect();
            write_cloud(&out_path, &moved)?;
        }
        say(format!("aligned source written to {}", out_path.display()));
    }
    if let Some(path) = json {
        let mut v = report_json(&method.name(out.precision), &out, &pose);
        if kind == MethodKind::Device {
            v["template_floor"] = floor.map(crate::device::short).into();
            v["verdict_max_residual"] = crate::device::short(method.max_residual).into();
        }
        write_json(&path, &v)?;
    }
    Ok(())
}

/// The verdict line: the registration's own (`registered`: the residual
/// and the source's shape) and, with `--viewpoint`, the view's, each
/// reason named.
fn trust_line(registered: bool, view: Option<bool>) -> String {
    let residual = "plane residual above the threshold, or a degenerate source";
    let seen = "it puts template points where the sensor saw past the object, or too few on the seen surface";
    match (registered, view) {
        (true, Some(true)) => "trust: RELIABLE (relative plane residual within the threshold, and the pose explains the view)".into(),
        (true, None) => "trust: RELIABLE (relative plane residual within the threshold)".into(),
        (true, Some(false)) => format!("trust: NOT RELIABLE - do not act on this pose ({seen})"),
        (false, Some(false)) => format!("trust: NOT RELIABLE - do not act on this pose ({residual}; and {seen})"),
        (false, _) => format!("trust: NOT RELIABLE - do not act on this pose ({residual})"),
    }
}

/// The whole result of `register` as JSON: pose in the files' frame
/// (quaternion w, x, y, z, translation, 4x4 row-major), the local origin
/// and the translation about it, and, for the device pipeline, the check.
fn report_json(method: &str, out: &methods::Outcome, pose: &FilePose) -> serde_json::Value {
    let mut v = serde_json::json!({
        "method": method,
        "iterations": out.iterations,
        "seconds": out.seconds,
        "quaternion_wxyz": out.pose.rotation,
        "translation": pose.translation,
        "matrix": pose.matrix(),
        "origin": pose.origin,
        "local_translation": pose.local_translation,
        "degenerate": out.degenerate.map(|d| format!("{d:?}")),
    });
    if let Some(c) = &out.check {
        v["residual"] = c.residual.into();
        v["relative_residual"] = c.relative_residual.into();
        v["fitness"] = c.fitness.into();
        v["inlier_rmse"] = c.inlier_rmse.into();
        v["plane_residual"] = c.plane_residual.into();
        v["relative_plane_residual"] = c.relative_plane_residual.into();
        v["hypothesis"] = c.hypothesis.into();
        v["passes"] = c.passes.into();
        v["lk_iterations"] = c.lk_iterations.into();
        v["icp_iterations"] = c.icp_iterations.into();
        v["saturated"] = c.saturated.into();
        v["out_of_range"] = c.out_of_range.into();
        v["reliable"] = out.reliable().unwrap_or(c.reliable).into();
        v["ambiguity"] = crate::ambiguity::json(&c.ambiguity, pose.origin);
    }
    if let Some(view) = &out.view {
        v["view_check"] = serde_json::json!({
            "supported": view.supported,
            "violations": view.violations,
            "occluded": view.occluded,
            "unobserved": view.unobserved,
            "passed": view.passed,
        });
    }
    v
}
