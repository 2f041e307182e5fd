//! `pcrnet register [TEMPLATE] SCENE --scene`: the object found in a
//! sensor frame and registered, as the device does it
//! (`Int8Model::locate`): a 16-bit depth PNG with `--intrinsics FILE`, or
//! an organised PCD. Prints the plane, the clusters, every registered
//! candidate and the winner's pose, and the same as JSON.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use pcrnet_core::Int8Model;
use pcrnet_core::locate::{Candidate, Located};
use pcrnet_core::scene::{self, DepthImage, Organised, OrganisedPoints};
use pcrnet_eval::cli::MethodOptions;
use pcrnet_io::depth;

use crate::device::DeviceModel;
use crate::register::{Output, Reading, json_on_stdout, say, write_json};
use crate::write_cloud;

/// Points gathered per candidate for its registration.
const CANDIDATE_POINTS: usize = 1024;

/// The scene flags of `register`.
pub(crate) struct SceneArgs<'a> {
    /// The template file, bound into the model (`None`: the blob's own).
    pub(crate) template: Option<&'a Path>,
    /// The frame: a depth PNG or an organised PCD.
    pub(crate) frame: &'a Path,
    /// The intrinsics JSON of a depth PNG.
    pub(crate) intrinsics: Option<&'a Path>,
    /// Candidates registered at most.
    pub(crate) candidates: usize,
    /// The template's up axis, for the sweep.
    pub(crate) up: Option<[f32; 3]>,
}

/// Runs `register --scene`.
pub(crate) fn run(
    args: SceneArgs,
    options: &MethodOptions,
    reading: &Reading,
    Output { aligned, json }: Output,
) -> anyhow::Result<()> {
    options.check()?;
    anyhow::ensure!(
        !options.refine_icp,
        "--refine-icp is register's host ICP after a network method; --scene runs the device pipeline, whose ICP --icp-iterations, --icp-distance and --icp-tolerance set"
    );
    anyhow::ensure!(
        (1..=pcrnet_core::locate::MAX_CANDIDATES).contains(&args.candidates),
        "--candidates must be 1 to {}",
        pcrnet_core::locate::MAX_CANDIDATES
    );
    let loaded = DeviceModel::load(options, args.template, reading, "register --scene")?;
    let model = Int8Model::from_bytes(&loaded.blob).with_context(|| loaded.label.clone())?;
    let extension = args
        .frame
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("png") => {
            let camera_path = args.intrinsics.context(
                "a depth PNG needs --intrinsics FILE: {\"fx\", \"fy\", \"cx\", \"cy\" (pixels), \"depth_scale\" (user units per raw value), \"invalid\"}",
            )?;
            let camera = depth::read_camera(camera_path)?;
            let frame = depth::read_png(args.frame)?;
            let image = DepthImage::new(
                &frame.depth,
                frame.width,
                frame.height,
                frame.width,
                camera.intrinsics(),
                camera.depth_scale,
                camera.invalid,
            )
            .with_context(|| format!("{} with {}", args.frame.display(), camera_path.display()))?;
            find(
                &image,
                &args,
                &model,
                &loaded,
                aligned.as_deref(),
                json.as_deref(),
            )
        }
        Some("pcd") => {
            anyhow::ensure!(
                args.intrinsics.is_none(),
                "--intrinsics is for a depth PNG; an organised PCD holds its points already"
            );
            let bytes = std::fs::read(args.frame)
                .with_context(|| format!("reading {}", args.frame.display()))?;
            let cloud = pcrnet_io::pcd::parse_organised(&bytes, reading.max_cloud_points())
                .with_context(|| args.frame.display().to_string())?;
            let organised = OrganisedPoints::new(&cloud.points, cloud.width)
                .with_context(|| args.frame.display().to_string())?;
            // Verification needs the projection: fitted to the points.
            let organised = match organised.estimate_intrinsics() {
                Some(k) => organised.with_intrinsics(k),
                None => organised,
            };
            find(
                &organised,
                &args,
                &model,
                &loaded,
                aligned.as_deref(),
                json.as_deref(),
            )
        }
        _ => anyhow::bail!(
            "{}: --scene reads a 16-bit depth PNG (with --intrinsics FILE) or an organised PCD (HEIGHT > 1); an unorganised cloud has no pixel grid to segment",
            args.frame.display()
        ),
    }
}

/// Locates the object in `frame` and reports it.
fn find<F: Organised>(
    frame: &F,
    args: &SceneArgs,
    model: &Int8Model,
    loaded: &DeviceModel,
    aligned: Option<&Path>,
    json: Option<&Path>,
) -> anyhow::Result<()> {
    // `--up`, else the axis the blob was exported with (none once a
    // TEMPLATE file is bound in: the axis was its template's).
    let mut scene_options = model.scene_options();
    if args.up.is_some() {
        scene_options.up = args.up;
    }
    let (width, height) = (frame.width(), frame.height());
    let mut labels = vec![0u16; scene::labels_len(width, height, scene_options.step)];
    let mut points = vec![[0f32; 3]; CANDIDATE_POINTS];
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let start = Instant::now();
    let located = model.locate(
        frame,
        &scene_options,
        args.candidates,
        &loaded.options,
        &mut labels,
        &mut points,
        &mut scratch,
    )?;
    let seconds = start.elapsed().as_secs_f64();

    let to_stdout = json_on_stdout(json);
    let say = |line: String| say(to_stdout, &line);
    say(loaded.model_line());
    if let Some(line) = loaded.floor_line() {
        say(line);
    }
    say(format!(
        "frame: {} ({width} x {height}); object radius {:.4} (the template's, user units); grid every {} pixels; time {:.1} ms",
        args.frame.display(),
        model.object_radius(),
        scene_options.step,
        seconds * 1e3
    ));
    // The bound a checked candidate is judged at (`Int8Model::locate`).
    let checked = pcrnet_core::locate::checked_bound(frame, &scene_options, &loaded.options);
    let bound = checked.unwrap_or(loaded.options.max_residual);
    if checked.is_some() {
        say(format!(
            "verdict: the check against the frame, and a relative plane residual of at most {bound:.4}"
        ));
    }
    let given = if args.up.is_some() {
        "--up"
    } else {
        "the blob's"
    };
    say(match (scene_options.up, located.segmentation.plane) {
        (Some(up), Some(_)) => format!(
            "registration: a sweep of {} turns about the plane's normal, the template's up axis {up:?} ({given}) along it",
            scene_options.yaws
        ),
        (Some(_), None) => format!("registration: the network's hypotheses (an up axis was given ({given}), but no plane was found to sweep about)"),
        (None, _) if loaded.template_points > 0 => "registration: the network's hypotheses (a TEMPLATE file was bound in, which has no up axis: give --up AXIS for an object standing on the plane in any yaw)".into(),
        (None, _) => "registration: the network's hypotheses (give --up AXIS, or export the model with --up, for an object standing on the plane in any yaw)".into(),
    });
    for line in report_lines(&located) {
        say(line);
    }
    let origin = loaded.origin;
    let file_translation = |t: [f32; 3]| [0, 1, 2].map(|k| f64::from(t[k]) + origin[k]);
    if let Some(best) = &located.best {
        let r = &best.registration;
        say(format!(
            "winner: candidate {} (cluster {}); quaternion (w, x, y, z) {:?}; translation {:?} (maps the frame's points onto the template file)",
            located.tried.iter().position(|c| c == best).unwrap_or(0),
            best.cluster,
            r.pose.rotation,
            file_translation(r.pose.translation)
        ));
        say(match (best.reliable, best.verification) {
            (true, Some(_)) => "trust: RELIABLE (plane residual within the threshold, and the pose explains the frame)".into(),
            (true, None) => "trust: RELIABLE (plane residual within the threshold; not checked against the frame)".into(),
            (false, _) => "trust: NOT RELIABLE - do not act on this pose (no candidate both fits the template and explains the frame)".into(),
        });
        for line in crate::ambiguity::lines(&r.ambiguity, origin) {
            say(line);
        }
        if let Some(path) = aligned {
            let cluster = located.segmentation.clusters.kept.get(best.cluster);
            let n = cluster.map_or(0, |c| {
                located
                    .segmentation
                    .gather(frame, &scene_options, &labels, c, &mut points)
            });
            let moved: Vec<[f64; 3]> = points[..n]
                .iter()
                .map(|&p| {
                    let q = r.pose.transform_point(p);
                    [0, 1, 2].map(|k| f64::from(q[k]) + origin[k])
                })
                .collect();
            write_cloud(path, &moved)?;
            say(format!(
                "the winner's points moved onto the template written to {}",
                path.display()
            ));
        }
    } else {
        say(
            "no candidate: no cluster of the object's size off the plane; nothing to register"
                .into(),
        );
    }
    if let Some(path) = json {
        let mut v = located_json(&located);
        v["frame"] = serde_json::json!({ "file": args.frame.display().to_string(), "width": width, "height": height });
        v["object_radius"] = model.object_radius().into();
        v["up"] = scene_options.up.into();
        v["seconds"] = seconds.into();
        v["origin"] = origin.into();
        v["template_floor"] = loaded.floor.map(crate::device::short).into();
        v["verdict_max_residual"] = crate::device::short(bound).into();
        if let Some(best) = &located.best {
            v["translation"] = file_translation(best.registration.pose.translation).into();
            v["ambiguity"] = crate::ambiguity::json(&best.registration.ambiguity, origin);
        }
        write_json(path, &v)?;
    }
    Ok(())
}

/// The plane, the clusters and the candidates, for a person.
fn report_lines(located: &Located) -> Vec<String> {
    let s = &located.segmentation;
    let c = &s.clusters;
    let mut lines = vec![match s.plane {
        Some(p) => format!(
            "plane: normal {:?}, {:.4} from the sensor; {} of {} grid cells on it",
            p.normal, p.offset, s.plane_cells, s.valid_cells
        ),
        None => format!(
            "plane: none found ({} grid cells hold a point)",
            s.valid_cells
        ),
    }];
    lines.push(format!(
        "clusters: {} kept; dropped: {} under the least cell count, {} of another size, {} beyond the {} largest",
        c.kept.len(),
        c.too_few_cells,
        c.wrong_radius,
        c.unmeasured,
        pcrnet_core::scene::cluster::MAX_CLUSTERS
    ));
    for (i, k) in c.kept.iter().enumerate() {
        lines.push(format!(
            "  cluster {i}: {} cells, centroid {:?}, radius {:.4}",
            k.cells, k.centroid, k.radius
        ));
    }
    for (i, t) in located.tried.iter().enumerate() {
        let check = match t.verification {
            Some(v) => format!(
                "against the frame: {} template points supported, {} in free space or beneath the plane, {} occluded, {} unobserved, {} outside the frame ({})",
                v.supported,
                v.violations,
                v.occluded,
                v.unobserved,
                v.outside,
                if v.passed { "passed" } else { "failed" }
            ),
            None => "not checked against the frame (its intrinsics are unknown)".into(),
        };
        lines.push(format!(
            "  candidate {i}: cluster {}, {} points, relative plane residual {:.4}, fitness {:.3}; {check}: {}",
            t.cluster,
            t.points,
            t.registration.relative_plane_residual,
            t.registration.fitness,
            if t.reliable { "reliable" } else { "not reliable" }
        ));
    }
    lines
}

/// One candidate as JSON.
fn candidate_json(c: &Candidate) -> serde_json::Value {
    let r = &c.registration;
    serde_json::json!({
        "cluster": c.cluster,
        "points": c.points,
        "quaternion_wxyz": r.pose.rotation,
        "relative_plane_residual": r.relative_plane_residual,
        "fitness": r.fitness,
        "hypothesis": r.hypothesis,
        "icp_iterations": r.icp_iterations,
        "registration_reliable": r.reliable,
        "verification": c.verification.map(|v| serde_json::json!({
            "supported": v.supported, "violations": v.violations, "occluded": v.occluded,
            "unobserved": v.unobserved, "outside": v.outside, "passed": v.passed,
        })),
        "reliable": c.reliable,
        "ambiguous": r.ambiguity.is_ambiguous(),
    })
}

/// The whole result as JSON.
fn located_json(located: &Located) -> serde_json::Value {
    let s = &located.segmentation;
    let c = &s.clusters;
    serde_json::json!({
        "plane": s.plane.map(|p| serde_json::json!({ "normal": p.normal, "offset": p.offset, "cells": s.plane_cells })),
        "valid_cells": s.valid_cells,
        "clusters": {
            "kept": c.kept.iter().map(|k| serde_json::json!({
                "cells": k.cells, "centroid": k.centroid, "radius": k.radius, "min": k.min, "max": k.max,
            })).collect::<Vec<_>>(),
            "too_few_cells": c.too_few_cells,
            "wrong_radius": c.wrong_radius,
            "unmeasured": c.unmeasured,
        },
        "candidates": located.tried.iter().map(candidate_json).collect::<Vec<_>>(),
        "winner": located.best.as_ref().and_then(|b| located.tried.iter().position(|c| c == b)),
        "quaternion_wxyz": located.best.as_ref().map(|b| b.registration.pose.rotation),
        "reliable": located.best.as_ref().is_some_and(|b| b.reliable),
    })
}

/// `pcrnet frame`: writes the harness frame of `model` (the shipped int8
/// model without one) to `out` as a 16-bit PNG and its intrinsics beside
/// it (`out` with extension `.json`).
pub(crate) fn write_frame(out: &Path, model: Option<&Path>) -> anyhow::Result<()> {
    use pcrnet_core::testing::scene as harness;
    let blob = match model {
        Some(path) => std::fs::read(path).with_context(|| format!("reading {}", path.display()))?,
        None => crate::register::shipped_model(pcrnet_eval::methods::MethodKind::Device)
            .context("no shipped int8 model in pcrnet")?
            .0
            .to_vec(),
    };
    let model = Int8Model::from_bytes(&blob).context(
        "the frame draws an int8 model's template: give --model the int8 blob (`pcrnet export` writes it)",
    )?;
    let (width, height) = (harness::HARNESS_WIDTH, harness::HARNESS_HEIGHT);
    let mut depth = vec![0u16; width * height];
    let mut template = vec![[0f32; 3]; model.template().len()];
    harness::harness_frame(&model, &mut template, &mut depth)?;
    let frame = depth::DepthFrame {
        depth,
        width,
        height,
    };
    depth::write_png(out, &frame).with_context(|| format!("writing {}", out.display()))?;
    let k = harness::Tabletop::tof_intrinsics();
    let camera = depth::CameraFile {
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        depth_scale: harness::DEPTH_SCALE,
        invalid: 0,
    };
    let json = out.with_extension("json");
    std::fs::write(&json, serde_json::to_string_pretty(&camera)? + "\n")
        .with_context(|| format!("writing {}", json.display()))?;
    // The same pixels raw, for firmware that links a frame (firmware-c).
    let raw = out.with_extension("u16");
    let bytes: Vec<u8> = frame.depth.iter().flat_map(|d| d.to_le_bytes()).collect();
    std::fs::write(&raw, bytes).with_context(|| format!("writing {}", raw.display()))?;
    println!(
        "wrote {} ({width} x {height}, millimetres), {} and {} (the pixels as little-endian u16, row by row); try: pcrnet register --scene {} --intrinsics {} --up z",
        out.display(),
        json.display(),
        raw.display(),
        out.display(),
        json.display()
    );
    Ok(())
}
