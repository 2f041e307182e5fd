//! The C firmware example (`firmware-c/`): built with Debian's
//! `arm-none-eabi-gcc` against `libpcrnet.a`, run under QEMU, and every
//! result it prints compared bit for bit with `pcrnet-core` on the host.
//!
//! The example prints each result twice: readable, and as an `@` line
//! with the bits of every value (`@ reg LABEL STATUS ...`,
//! `@ pose LABEL STATUS ...`, `@ view LABEL STATUS ...`, `@ locate ...`,
//! `@ done`). The host recomputes each labelled
//! call and formats it the same way through the C API's own conversions,
//! so a difference names the call and the field.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use anyhow::{Context, bail, ensure};
use pcrnet::{PcrnetRegistration, PcrnetStatus};
use pcrnet_core::{Int8Model, Options};

use crate::qemu;

/// Calls the example always makes; `every-start` follows only an
/// unreliable `default`.
const REQUIRED: [&str; 6] = [
    "reg default",
    "reg network",
    "pose iterated",
    "view above",
    "locate sweep",
    "reg nan",
];

/// Names of the values of an `@ locate` line after its status, before the
/// registration's ([`REG_FIELDS`]).
const LOCATE_FIELDS: [&str; 16] = [
    "found",
    "reliable",
    "verified",
    "has_plane",
    "cluster",
    "clusters_kept",
    "candidates_tried",
    "supported",
    "violations",
    "occluded",
    "unobserved",
    "outside",
    "plane_normal x",
    "plane_normal y",
    "plane_normal z",
    "plane_offset",
];

/// Names of the values of an `@ reg` line after its status.
const REG_FIELDS: [&str; 39] = [
    "rotation w",
    "rotation x",
    "rotation y",
    "rotation z",
    "translation x",
    "translation y",
    "translation z",
    "residual",
    "relative_residual",
    "plane_residual",
    "relative_plane_residual",
    "fitness",
    "inlier_rmse",
    "hypothesis",
    "passes",
    "lk_iterations",
    "icp_iterations",
    "saturated",
    "out_of_range",
    "degenerate",
    "reliable",
    "has_free_axis",
    "free_axis x",
    "free_axis y",
    "free_axis z",
    "free_axis_point x",
    "free_axis_point y",
    "free_axis_point z",
    "free_axis_stiffness",
    "has_turn",
    "turn_rotation w",
    "turn_rotation x",
    "turn_rotation y",
    "turn_rotation z",
    "turn_translation x",
    "turn_translation y",
    "turn_translation z",
    "turn_degrees",
    "turn_relative_plane_residual",
];

fn hex(values: &[f32]) -> String {
    values
        .iter()
        .map(|v| format!(" {:08x}", v.to_bits()))
        .collect()
}

/// The `@ reg` line the example prints for this result.
fn reg_line(label: &str, result: Result<PcrnetRegistration, PcrnetStatus>) -> String {
    match result {
        Err(s) => format!("@ reg {label} {}", s as i32),
        Ok(r) => format!("@ reg {label} 0{}", registration_words(&r)),
    }
}

/// Every value of a registration as the example prints it after a line's
/// head (each word with its leading space).
fn registration_words(r: &PcrnetRegistration) -> String {
    let mut line = format!(
        "{}{}{}",
        hex(&r.rotation),
        hex(&r.translation),
        hex(&[
            r.residual,
            r.relative_residual,
            r.plane_residual,
            r.relative_plane_residual,
            r.fitness,
            r.inlier_rmse,
        ])
    );
    for count in [
        r.hypothesis,
        r.passes,
        r.lk_iterations,
        r.icp_iterations,
        r.saturated,
        r.out_of_range,
        r.degenerate,
        u32::from(r.reliable),
        u32::from(r.has_free_axis),
    ] {
        line += &format!(" {count}");
    }
    line += &hex(&r.free_axis);
    line += &hex(&r.free_axis_point);
    line += &hex(&[r.free_axis_stiffness]);
    line += &format!(" {}", u8::from(r.has_turn));
    line += &hex(&r.turn_rotation);
    line += &hex(&r.turn_translation);
    line += &hex(&[r.turn_degrees, r.turn_relative_plane_residual]);
    line
}

/// The `@ locate LABEL` line the example prints for `pcrnet_locate` on its
/// frame (`sweep`), or for `pcrnet_follow` from that result (`follow`),
/// computed on the host with `Int8Model::locate` and `Int8Model::follow`
/// and the C API's own conversions (scene options in, `PcrnetLocated` out).
fn locate_line(model: &Int8Model<'_>, depth: &[u16], scratch: &mut [i8], label: &str) -> String {
    use pcrnet::{PcrnetLocated, PcrnetSceneOptions};
    use pcrnet_core::testing::scene as harness;
    // As firmware-c/main.c sets them: the defaults, up z.
    let scene = PcrnetSceneOptions {
        has_up: true,
        up: [0.0, 0.0, 1.0],
        ..PcrnetSceneOptions::default()
    };
    let options = scene.scene_options(model.object_radius());
    let mut labels = vec![0u16; pcrnet_core::scene::labels_len(FRAME.0, FRAME.1, options.step)];
    let mut points = vec![[0f32; 3]; 512];
    let image = match harness::harness_image(depth) {
        Ok(image) => image,
        Err(e) => return format!("@ locate {label} {}", PcrnetStatus::from(e) as i32),
    };
    let located = model.locate(
        &image,
        &options,
        scene.candidates as usize,
        &Options::default(),
        &mut labels,
        &mut points,
        scratch,
    );
    // `follow`: the C example follows a reliable sweep into the same frame,
    // its plane copied into the scene options (`pcrnet_follow` passes no
    // plane of its own).
    let result = match (label, located) {
        ("follow", Ok(l)) => {
            let Some(best) = l.best.filter(|b| b.reliable) else {
                return "@ locate follow (no reliable sweep to follow)".into();
            };
            let next = PcrnetSceneOptions {
                has_plane: l.segmentation.plane.is_some(),
                plane_normal: l.segmentation.plane.map_or([0.0; 3], |p| p.normal),
                plane_offset: l.segmentation.plane.map_or(0.0, |p| p.offset),
                ..scene
            };
            model.follow(
                &image,
                &next.scene_options(model.object_radius()),
                &best.registration.pose,
                None,
                &Options::default(),
                &mut labels,
                &mut points,
                scratch,
            )
        }
        (_, located) => located,
    };
    let out = match result {
        Ok(l) => PcrnetLocated::from(&l),
        Err(e) => return format!("@ locate {label} {}", PcrnetStatus::from(e) as i32),
    };
    let counts = [
        u32::from(out.found),
        u32::from(out.reliable),
        u32::from(out.verified),
        u32::from(out.has_plane),
        out.cluster,
        out.clusters_kept,
        out.candidates_tried,
        out.supported,
        out.violations,
        out.occluded,
        out.unobserved,
        out.outside,
    ];
    let counts: String = counts.iter().map(|c| format!(" {c}")).collect();
    format!(
        "@ locate {label} 0{counts}{}{}{}",
        hex(&out.plane_normal),
        hex(&[out.plane_offset]),
        registration_words(&out.registration)
    )
}

/// The size of the frame the example links (the QEMU harness's).
const FRAME: (usize, usize) = (
    pcrnet_core::testing::scene::HARNESS_WIDTH,
    pcrnet_core::testing::scene::HARNESS_HEIGHT,
);

/// The frame the example links for `blob`: the harness's, drawn with the
/// model's template ([`pcrnet_core::testing::scene::harness_frame`]).
pub fn frame(blob: &[u8]) -> anyhow::Result<Vec<u16>> {
    let model = Int8Model::from_bytes(blob).context("the host rejects the example's model")?;
    let mut depth = vec![0u16; FRAME.0 * FRAME.1];
    let mut template = vec![[0f32; 3]; model.template().len()];
    pcrnet_core::testing::scene::harness_frame(&model, &mut template, &mut depth)?;
    Ok(depth)
}

/// What the host computes for the call an `@` line reports, as that line.
fn expected_line(
    model: &Int8Model<'_>,
    (source, depth): (&[[f32; 3]], &[u16]),
    kind: &str,
    label: &str,
    scratch: &mut [i8],
) -> anyhow::Result<String> {
    let register = |cloud: &[[f32; 3]], options: Options, scratch: &mut [i8]| {
        model
            .register(cloud, &options, scratch)
            .map(|r| PcrnetRegistration::from(&r))
            .map_err(PcrnetStatus::from)
    };
    Ok(match (kind, label) {
        ("reg", "default") => reg_line(label, register(source, Options::default(), scratch)),
        ("reg", "every-start") => {
            let every = Options {
                hypotheses: u32::MAX as usize,
                ..Options::default()
            };
            reg_line(label, register(source, every, scratch))
        }
        ("reg", "network") => reg_line(label, register(source, Options::network_only(), scratch)),
        ("reg", "nan") => {
            let mut cloud = source.to_vec();
            cloud[0][0] = f32::NAN;
            reg_line(label, register(&cloud, Options::default(), scratch))
        }
        ("pose", "iterated") => match model.network_pose(source, 3, 0.0, scratch) {
            Ok((p, n)) => format!(
                "@ pose {label} 0 {n}{}{}",
                hex(&p.rotation),
                hex(&p.translation)
            ),
            Err(e) => format!("@ pose {label} {}", PcrnetStatus::from(e) as i32),
        },
        ("locate", label @ ("sweep" | "follow")) => locate_line(model, depth, scratch, label),
        ("view", "above") => {
            let mut view = vec![0f32; pcrnet_core::scene::view::buffer_len(32)];
            match model.register_view(source, VIEWPOINT, &Options::default(), scratch, &mut view) {
                Ok(v) => {
                    // The C API's `reliable` is both verdicts.
                    let r = PcrnetRegistration::from(&pcrnet_core::Registration {
                        reliable: v.reliable,
                        ..v.registration
                    });
                    let c = v.view;
                    format!(
                        "@ view {label} 0{} {} {} {} {} {}",
                        registration_words(&r),
                        c.supported,
                        c.violations,
                        c.occluded,
                        c.unobserved,
                        u8::from(c.passed)
                    )
                }
                Err(e) => format!("@ view {label} {}", PcrnetStatus::from(e) as i32),
            }
        }
        _ => bail!("the C example printed an unknown call `@ {kind} {label}`"),
    })
}

/// Where the C example's sensor stands for its `@ view above` line.
const VIEWPOINT: [f32; 3] = [0.0, 0.0, 3.0];

/// The first field where two `@` lines differ, named.
fn difference(kind: &str, device: &str, host: &str) -> String {
    let d: Vec<&str> = device.split_whitespace().skip(4).collect();
    let h: Vec<&str> = host.split_whitespace().skip(4).collect();
    let status = |line: &str| line.split_whitespace().nth(3).unwrap_or("").to_string();
    if status(device) != status(host) {
        return format!(
            "status {} on the device, {} on the host",
            status(device),
            status(host)
        );
    }
    for (i, (a, b)) in d.iter().zip(&h).enumerate() {
        if a != b {
            let name = match kind {
                "reg" => REG_FIELDS.get(i).copied().unwrap_or("extra value"),
                "view" => REG_FIELDS
                    .iter()
                    .chain(&[
                        "supported",
                        "violations",
                        "occluded",
                        "unobserved",
                        "passed",
                    ])
                    .nth(i)
                    .copied()
                    .unwrap_or("extra value"),
                "locate" => LOCATE_FIELDS
                    .iter()
                    .chain(&REG_FIELDS)
                    .nth(i)
                    .copied()
                    .unwrap_or("extra value"),
                _ if i == 0 => "passes",
                _ => ["qw", "qx", "qy", "qz", "tx", "ty", "tz"]
                    .get(i - 1)
                    .copied()
                    .unwrap_or("extra value"),
            };
            return format!("{name}: {a} on the device, {b} on the host");
        }
    }
    format!("{} values on the device, {} on the host", d.len(), h.len())
}

/// Compares every `@` line of the example's output with the host.
/// Returns the number of calls compared; fails naming each difference.
pub fn check(output: &str, blob: &[u8], source: &[[f32; 3]]) -> anyhow::Result<usize> {
    let model = Int8Model::from_bytes(blob).context("the host rejects the example's model")?;
    let mut scratch = vec![0i8; model.scratch_len(pcrnet_core::MAX_TILE)];
    let depth = frame(blob)?;
    let mut seen = Vec::new();
    let mut failures = Vec::new();
    let mut done = false;
    for line in output.lines().filter(|l| l.starts_with("@ ")) {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["@", "done"] => done = true,
            ["@", kind, label, ..] => {
                let host = expected_line(&model, (source, &depth), kind, label, &mut scratch)?;
                if host != line {
                    failures.push(format!("{kind} {label}: {}", difference(kind, line, &host)));
                }
                seen.push(format!("{kind} {label}"));
            }
            _ => bail!("malformed line from the C example: {line}"),
        }
    }
    for call in REQUIRED {
        ensure!(
            seen.iter().any(|s| s == call),
            "the C example did not report `{call}`"
        );
    }
    ensure!(done, "the C example did not finish (no `@ done`)");
    ensure!(failures.is_empty(), "{}", failures.join("\n"));
    Ok(seen.len())
}

/// Builds the example with its Makefile (which builds `libpcrnet.a` with
/// cargo) into `target/firmware-c`, and returns the ELF. The library is
/// built with `prove-no-panic`: the link itself proves that no panic path
/// is reachable from the C functions the example calls.
pub fn build(root: &Path) -> anyhow::Result<std::path::PathBuf> {
    let build = root.join("target").join("firmware-c");
    // The depth frame the example links (the Makefile's FRAME).
    let blob = std::fs::read(root.join("models/embedded-default-int8.pcrn"))?;
    let bytes: Vec<u8> = frame(&blob)?.iter().flat_map(|d| d.to_le_bytes()).collect();
    std::fs::create_dir_all(&build)?;
    let frame_file = build.join("frame.u16");
    if std::fs::read(&frame_file).ok().as_deref() != Some(&bytes[..]) {
        std::fs::write(&frame_file, &bytes)
            .with_context(|| format!("writing {}", frame_file.display()))?;
    }
    let status = Command::new("make")
        .arg("-C")
        .arg(root.join("firmware-c"))
        .arg(format!("BUILD={}", build.display()))
        .arg(format!("FRAME={}", frame_file.display()))
        .arg("CAPI_FEATURES=prove-no-panic")
        .arg(format!(
            "CARGO={}",
            std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
        ))
        .env_remove("CARGO_TARGET_DIR")
        .status()
        .context("running make (Debian package `make`)")?;
    ensure!(
        status.success(),
        "building firmware-c failed ({status}); it needs Debian's gcc-arm-none-eabi and \
         libnewlib-arm-none-eabi (`cargo xtask c-example` installs them)"
    );
    Ok(build.join("pcrnet-c-example.elf"))
}

/// Builds and runs the example under QEMU and compares it with the host.
pub fn run(timeout: Duration) -> anyhow::Result<()> {
    let root = qemu::workspace_root();
    let elf = build(&root)?;
    let output = qemu::run_with_timeout(qemu::qemu_command(&qemu::BOARDS[0], &elf, None), timeout)?;
    print!("{output}");
    let blob = std::fs::read(root.join("models/embedded-default-int8.pcrn"))?;
    let source = crate::vectors::read_cloud(&root.join("models/embedded-default-source.f32"))?;
    let n = check(&output, &blob, &source)?;
    println!("C example: {n} calls bit-identical with the host");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the example prints, as the host computes it.
    fn host_output(blob: &[u8], source: &[[f32; 3]]) -> String {
        let model = Int8Model::from_bytes(blob).unwrap();
        let mut scratch = vec![0i8; model.scratch_len(1)];
        let depth = frame(blob).unwrap();
        let mut out = String::from("pcrnet C example\n");
        for call in REQUIRED {
            let (kind, label) = call.split_once(' ').unwrap();
            let inputs = (source, &depth[..]);
            out += &expected_line(&model, inputs, kind, label, &mut scratch).unwrap();
            out.push('\n');
        }
        out + "@ done\n"
    }

    #[test]
    fn the_check_passes_the_hosts_own_output_and_names_a_changed_field() {
        let root = qemu::workspace_root();
        let blob = std::fs::read(root.join("models/embedded-default-int8.pcrn")).unwrap();
        let source =
            crate::vectors::read_cloud(&root.join("models/embedded-default-source.f32")).unwrap();
        let source = &source[..64];
        let good = host_output(&blob, source);
        assert_eq!(check(&good, &blob, source).unwrap(), REQUIRED.len());

        // One bit of the default registration's plane residual, flipped.
        let line = good
            .lines()
            .find(|l| l.starts_with("@ reg default"))
            .unwrap();
        let mut words: Vec<String> = line.split_whitespace().map(String::from).collect();
        let at = 4 + REG_FIELDS
            .iter()
            .position(|f| *f == "plane_residual")
            .unwrap();
        let value = u32::from_str_radix(&words[at], 16).unwrap() ^ 1;
        words[at] = format!("{value:08x}");
        let bad = good.replace(line, &words.join(" "));
        let err = check(&bad, &blob, source).unwrap_err().to_string();
        assert!(err.contains("reg default: plane_residual"), "{err}");

        // A status the host does not give; a missing call; no end marker.
        let bad = good.replace("@ reg nan -31", "@ reg nan -32");
        let err = check(&bad, &blob, source).unwrap_err().to_string();
        assert!(
            err.contains("status -32 on the device, -31 on the host"),
            "{err}"
        );
        let bad: String = good
            .lines()
            .filter(|l| !l.starts_with("@ pose"))
            .map(|l| format!("{l}\n"))
            .collect();
        let err = check(&bad, &blob, source).unwrap_err().to_string();
        assert!(err.contains("did not report `pose iterated`"), "{err}");
        let err = check(&good.replace("@ done", ""), &blob, source)
            .unwrap_err()
            .to_string();
        assert!(err.contains("did not finish"), "{err}");
    }
}
