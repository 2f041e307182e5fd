//! Parsing the device's lines and comparing them with the host's values.

use std::collections::BTreeMap;

use pcrnet_core::POSE_DIM;

use crate::tracking::{self, DeviceTrack};
use crate::vectors::{Expected, Iterative, RegistrationBits, RegistrationOutcome};

/// What the device printed for one case.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceResult {
    /// The outputs, in the same form as the host's.
    pub outputs: Expected,
    /// Instructions spent by `encode_tiled` alone (successful cases).
    pub encode_instructions: u64,
    /// Instructions spent by `infer_tiled` + pose (successful cases).
    pub infer_instructions: u64,
    /// Peak stack bytes during the case.
    pub stack: usize,
}

/// What the device printed for one `register` call.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceRegistration {
    /// The outputs, in the same form as the host's.
    pub outcome: RegistrationOutcome,
    /// Instructions spent by the call.
    pub instructions: u64,
    /// Peak stack bytes during the call.
    pub stack: usize,
}

/// Everything the device printed.
#[derive(Debug, Default)]
pub struct DeviceRun {
    /// `(expected instructions, measured instructions)` of the calibration loop.
    pub calibration: Option<(u64, u64)>,
    /// Static RAM of the runner.
    pub static_ram: Option<usize>,
    /// Per case index.
    pub cases: BTreeMap<usize, DeviceResult>,
    /// Iterative registrations, per case index.
    pub iterative: BTreeMap<usize, Iterative>,
    /// `register` calls, per (case index, option set index).
    pub registrations: BTreeMap<(usize, usize), DeviceRegistration>,
    /// Tracking steps, per (case index, option set index, start name).
    pub tracks: BTreeMap<(usize, usize, String), DeviceTrack>,
    /// Feature-space checks, per (case index, option set index).
    pub features: BTreeMap<(usize, usize), crate::feature::DeviceFeature>,
    /// View checks, per (case index, option set index).
    pub views: BTreeMap<(usize, usize), crate::view::DeviceView>,
    /// The scene path, per model index.
    pub scenes: crate::scene::Scenes,
    /// Load verdict per model (`ok int8`, `ok f32`, `error ...`; see
    /// [`crate::hostile::load_verdict`]).
    pub loads: BTreeMap<usize, String>,
    /// Peak stack bytes of parsing each model's blob.
    pub load_stacks: BTreeMap<usize, usize>,
    /// Lines that were not understood (reported, and they fail the run).
    pub unparsed: Vec<String>,
    /// Whether the runner printed its closing `done`.
    pub done: bool,
}

const POSE_NAMES: [&str; POSE_DIM] = ["qw", "qx", "qy", "qz", "tx", "ty", "tz"];

fn parse_ok(rest: &[&str]) -> Option<DeviceResult> {
    let [enc, total, stack, "feature", hex, "head", tail @ ..] = rest else {
        return None;
    };
    let feature = (0..hex.len() / 2)
        .map(|i| {
            u8::from_str_radix(hex.get(2 * i..2 * i + 2)?, 16)
                .ok()
                .map(|b| b as i8)
        })
        .collect::<Option<Vec<i8>>>()?;
    let mut head = [0i32; POSE_DIM];
    for (h, s) in head.iter_mut().zip(tail) {
        *h = s.parse().ok()?;
    }
    let tail = tail.get(POSE_DIM..)?;
    let pose = match tail {
        ["pose", bits @ ..] if bits.len() == POSE_DIM => {
            let mut out = [0u32; POSE_DIM];
            for (o, s) in out.iter_mut().zip(bits) {
                *o = u32::from_str_radix(s, 16).ok()?;
            }
            Ok(out)
        }
        ["pose_error", e @ ..] => Err(e.join(" ")),
        _ => return None,
    };
    Some(DeviceResult {
        outputs: Expected::Ok {
            feature,
            head,
            pose,
        },
        encode_instructions: enc.parse().ok()?,
        infer_instructions: total.parse().ok()?,
        stack: stack.parse().ok()?,
    })
}

fn hex_bits(s: &str) -> Option<u32> {
    u32::from_str_radix(s, 16).ok()
}

/// `instructions stack qw qx qy qz tx ty tz residual relative fitness rmse
/// plane relative_plane hypothesis passes lk_iterations icp_iterations
/// saturated out_of_range degenerate reliable axis turn`.
pub fn parse_registration(rest: &[&str]) -> Option<DeviceRegistration> {
    let [
        instructions,
        stack,
        qw,
        qx,
        qy,
        qz,
        tx,
        ty,
        tz,
        residual,
        relative,
        fitness,
        rmse,
        plane,
        relative_plane,
        hypothesis,
        passes,
        lk,
        icp,
        saturated,
        out_of_range,
        degenerate,
        reliable,
        axis,
        turn,
    ] = rest
    else {
        return None;
    };
    let mut pose = [0u32; POSE_DIM];
    for (o, s) in pose.iter_mut().zip([qw, qx, qy, qz, tx, ty, tz]) {
        *o = hex_bits(s)?;
    }
    Some(DeviceRegistration {
        outcome: Ok(RegistrationBits {
            pose,
            residual: hex_bits(residual)?,
            relative_residual: hex_bits(relative)?,
            fitness: hex_bits(fitness)?,
            inlier_rmse: hex_bits(rmse)?,
            plane_residual: hex_bits(plane)?,
            relative_plane_residual: hex_bits(relative_plane)?,
            hypothesis: hypothesis.parse().ok()?,
            passes: passes.parse().ok()?,
            lk_iterations: lk.parse().ok()?,
            icp_iterations: icp.parse().ok()?,
            saturated: saturated.parse().ok()?,
            out_of_range: out_of_range.parse().ok()?,
            degenerate: degenerate.to_string(),
            reliable: reliable.parse().ok()?,
            ambiguity: format!("{axis} {turn}"),
        }),
        instructions: instructions.parse().ok()?,
        stack: stack.parse().ok()?,
    })
}

/// Parses the runner's output.
pub fn parse(stdout: &str) -> DeviceRun {
    let mut run = DeviceRun::default();
    for line in stdout.lines().map(str::trim).filter(|l| !l.is_empty()) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let parsed = match words.as_slice() {
            ["calibration", want, got] => want
                .parse()
                .ok()
                .zip(got.parse().ok())
                .map(|c| run.calibration = Some(c)),
            ["static_ram", n] => n.parse().ok().map(|n| run.static_ram = Some(n)),
            ["done"] => {
                run.done = true;
                Some(())
            }
            ["model", m, "scene", rest @ ..] => {
                crate::scene::parse_line(m, rest, &mut run.scenes).then_some(())
            }
            ["model", m, "load_stack", n] => m.parse().ok().zip(n.parse().ok()).map(|(m, n)| {
                run.load_stacks.insert(m, n);
            }),
            ["model", m, "load", verdict @ ..] if !verdict.is_empty() => m.parse().ok().map(|m| {
                run.loads.insert(m, verdict.join(" "));
            }),
            ["case", c, "ok", rest @ ..] => c.parse().ok().zip(parse_ok(rest)).map(|(c, r)| {
                run.cases.insert(c, r);
            }),
            ["case", c, "iter", "ok", n, bits @ ..] if bits.len() == POSE_DIM => {
                let mut out = [0u32; POSE_DIM];
                let ok = out
                    .iter_mut()
                    .zip(bits)
                    .all(|(o, b)| u32::from_str_radix(b, 16).map(|v| *o = v).is_ok());
                c.parse()
                    .ok()
                    .zip(n.parse().ok())
                    .filter(|_| ok)
                    .map(|(c, n)| {
                        run.iterative.insert(c, Ok((n, out)));
                    })
            }
            ["case", c, "iter", "error", error @ ..] => c.parse().ok().map(|c| {
                run.iterative.insert(c, Err(error.join(" ")));
            }),
            ["case", c, "track", rest @ ..] => tracking::parse_line(c, rest).map(|(key, step)| {
                run.tracks.insert(key, step);
            }),
            ["case", c, "feature", rest @ ..] => {
                crate::feature::parse_line(c, rest).map(|(key, check)| {
                    run.features.insert(key, check);
                })
            }
            ["case", c, "view", rest @ ..] => {
                crate::view::parse_line(c, rest).map(|(key, check)| {
                    run.views.insert(key, check);
                })
            }
            ["case", c, "reg", k, "ok", rest @ ..] => c
                .parse()
                .ok()
                .zip(k.parse().ok())
                .zip(parse_registration(rest))
                .map(|(key, r)| {
                    run.registrations.insert(key, r);
                }),
            [
                "case",
                c,
                "reg",
                k,
                "error",
                instructions,
                stack,
                error @ ..,
            ] if !error.is_empty() => c
                .parse()
                .ok()
                .zip(k.parse().ok())
                .zip(instructions.parse().ok().zip(stack.parse().ok()))
                .map(|(key, (instructions, stack))| {
                    run.registrations.insert(
                        key,
                        DeviceRegistration {
                            outcome: Err(error.join(" ")),
                            instructions,
                            stack,
                        },
                    );
                }),
            ["case", c, "error", encoded, error @ ..] => c
                .parse()
                .ok()
                .zip(encoded.parse().ok())
                .map(|(c, encoded)| {
                    run.cases.insert(
                        c,
                        DeviceResult {
                            outputs: Expected::Err {
                                encoded,
                                error: error.join(" "),
                            },
                            encode_instructions: 0,
                            infer_instructions: 0,
                            stack: 0,
                        },
                    );
                }),
            _ => None,
        };
        if parsed.is_none() {
            run.unparsed.push(line.to_string());
        }
    }
    run
}

/// How an iterative registration differs between host and device, if it does.
pub fn iterative_difference(host: &Iterative, device: Option<&Iterative>) -> Option<String> {
    match (host, device) {
        (_, None) => Some("iterative: no output from the device".into()),
        (Ok((hn, h)), Some(Ok((dn, d)))) => {
            if hn != dn {
                return Some(format!("iterative passes: host {hn} device {dn}"));
            }
            (0..POSE_DIM).find(|&i| h[i] != d[i]).map(|i| {
                format!(
                    "iterative pose {}: host {:08x} device {:08x}",
                    POSE_NAMES[i], h[i], d[i]
                )
            })
        }
        (h, Some(d)) if h == d => None,
        (h, Some(d)) => Some(format!("iterative: host {h:?} device {d:?}")),
    }
}

fn f32_difference(name: &str, h: u32, d: u32) -> Option<String> {
    (h != d).then(|| {
        format!(
            "{name}: host {h:08x} ({}) device {d:08x} ({})",
            f32::from_bits(h),
            f32::from_bits(d)
        )
    })
}

fn int_difference<T: PartialEq + std::fmt::Display>(name: &str, h: T, d: T) -> Option<String> {
    (h != d).then(|| format!("{name}: host {h} device {d}"))
}

/// How a `register` call differs between host and device (the first field
/// that does, in declaration order), if it does.
pub fn registration_difference(
    host: &RegistrationOutcome,
    device: Option<&RegistrationOutcome>,
) -> Option<String> {
    match (host, device) {
        (_, None) => Some("no output from the device".into()),
        (Ok(h), Some(Ok(d))) => (0..POSE_DIM)
            .find_map(|i| f32_difference(&format!("pose {}", POSE_NAMES[i]), h.pose[i], d.pose[i]))
            .or_else(|| f32_difference("residual", h.residual, d.residual))
            .or_else(|| {
                f32_difference(
                    "relative_residual",
                    h.relative_residual,
                    d.relative_residual,
                )
            })
            .or_else(|| f32_difference("fitness", h.fitness, d.fitness))
            .or_else(|| f32_difference("inlier_rmse", h.inlier_rmse, d.inlier_rmse))
            .or_else(|| f32_difference("plane_residual", h.plane_residual, d.plane_residual))
            .or_else(|| {
                f32_difference(
                    "relative_plane_residual",
                    h.relative_plane_residual,
                    d.relative_plane_residual,
                )
            })
            .or_else(|| int_difference("hypothesis", h.hypothesis, d.hypothesis))
            .or_else(|| int_difference("passes", h.passes, d.passes))
            .or_else(|| int_difference("lk_iterations", h.lk_iterations, d.lk_iterations))
            .or_else(|| int_difference("icp_iterations", h.icp_iterations, d.icp_iterations))
            .or_else(|| int_difference("saturated", h.saturated, d.saturated))
            .or_else(|| int_difference("out_of_range", h.out_of_range, d.out_of_range))
            .or_else(|| int_difference("degenerate", &h.degenerate, &d.degenerate))
            .or_else(|| int_difference("reliable", h.reliable, d.reliable))
            .or_else(|| int_difference("ambiguity", &h.ambiguity, &d.ambiguity)),
        (h, Some(d)) if h == d => None,
        (h, Some(d)) => Some(format!("host {h:?} device {d:?}")),
    }
}

/// The first value that differs between host and device, if any.
pub fn first_difference(host: &Expected, device: &Expected) -> Option<String> {
    match (host, device) {
        (
            Expected::Ok {
                feature: hf,
                head: hh,
                pose: hp,
            },
            Expected::Ok {
                feature: df,
                head: dh,
                pose: dp,
            },
        ) => {
            if hf.len() != df.len() {
                return Some(format!(
                    "feature length: host {} device {}",
                    hf.len(),
                    df.len()
                ));
            }
            if let Some(i) = (0..hf.len()).find(|&i| hf[i] != df[i]) {
                return Some(format!("feature[{i}]: host {} device {}", hf[i], df[i]));
            }
            if let Some(i) = (0..POSE_DIM).find(|&i| hh[i] != dh[i]) {
                return Some(format!("head[{i}]: host {} device {}", hh[i], dh[i]));
            }
            match (hp, dp) {
                (Ok(h), Ok(d)) => (0..POSE_DIM).find(|&i| h[i] != d[i]).map(|i| {
                    format!(
                        "pose {}: host {:08x} ({}) device {:08x} ({})",
                        POSE_NAMES[i],
                        h[i],
                        f32::from_bits(h[i]),
                        d[i],
                        f32::from_bits(d[i])
                    )
                }),
                (h, d) if h == d => None,
                (h, d) => Some(format!("pose: host {h:?} device {d:?}")),
            }
        }
        (h, d) if h == d => None,
        (h, d) => Some(format!("host {h:?}, device {d:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_compares() {
        let out = "calibration 2000000 2000000\nstatic_ram 65600\n\
                   case 0 ok 100 250 512 feature 7f80ff00 head 1 -2 3 4 5 6 7 pose 3f800000 0 0 0 0 0 0\n\
                   case 0 iter ok 3 3f800000 0 0 0 0 0 1\n\
                   case 0 reg 0 ok 1000 600 3f800000 0 0 0 0 0 0 3c23d70a 3c23d70a 3f800000 0 3c23d70a 3c23d70a 1 1 5 7 12 2 none true none none\n\
                   case 1 error false EmptyCloud\ncase 1 iter error EmptyCloud\n\
                   case 1 reg 0 error 20 100 InvalidOption { what: \"hypotheses must be at least 1\" }\n\
                   case 1 reg 1 error 20 100 EmptyCloud\ndone\n";
        let run = parse(out);
        assert!(run.done && run.unparsed.is_empty());
        assert_eq!(run.calibration, Some((2_000_000, 2_000_000)));
        let c0 = &run.cases[&0];
        assert_eq!(c0.encode_instructions, 100);
        let host = Expected::Ok {
            feature: vec![127, -128, -1, 0],
            head: [1, -2, 3, 4, 5, 6, 7],
            pose: Ok([0x3f80_0000, 0, 0, 0, 0, 0, 0]),
        };
        assert_eq!(first_difference(&host, &c0.outputs), None);
        let mut other = host.clone();
        if let Expected::Ok { feature, .. } = &mut other {
            feature[2] = 5;
        }
        assert_eq!(
            first_difference(&other, &c0.outputs).as_deref(),
            Some("feature[2]: host 5 device -1")
        );
        let err = Expected::Err {
            encoded: false,
            error: "EmptyCloud".into(),
        };
        assert_eq!(first_difference(&err, &run.cases[&1].outputs), None);
        assert!(parse("case 3 ok garbage").unparsed.len() == 1);
        let it: Iterative = Ok((3, [0x3f80_0000, 0, 0, 0, 0, 0, 1]));
        assert_eq!(iterative_difference(&it, run.iterative.get(&0)), None);
        assert_eq!(
            iterative_difference(&Ok((2, [0; POSE_DIM])), run.iterative.get(&0)).as_deref(),
            Some("iterative passes: host 2 device 3")
        );
        let err: Iterative = Err("EmptyCloud".into());
        assert_eq!(iterative_difference(&err, run.iterative.get(&1)), None);

        let reg = &run.registrations[&(0, 0)];
        assert_eq!((reg.instructions, reg.stack), (1000, 600));
        let host = RegistrationBits {
            pose: [0x3f80_0000, 0, 0, 0, 0, 0, 0],
            residual: 0x3c23_d70a,
            relative_residual: 0x3c23_d70a,
            fitness: 0x3f80_0000,
            inlier_rmse: 0,
            plane_residual: 0x3c23_d70a,
            relative_plane_residual: 0x3c23_d70a,
            hypothesis: 1,
            passes: 1,
            lk_iterations: 5,
            icp_iterations: 7,
            saturated: 12,
            out_of_range: 2,
            degenerate: "none".into(),
            reliable: true,
            ambiguity: "none none".into(),
        };
        assert_eq!(
            registration_difference(&Ok(host.clone()), Some(&reg.outcome)),
            None
        );
        let mut other = host.clone();
        other.icp_iterations = 8;
        assert_eq!(
            registration_difference(&Ok(other), Some(&reg.outcome)).as_deref(),
            Some("icp_iterations: host 8 device 7")
        );
        let mut other = host.clone();
        other.lk_iterations = 4;
        assert_eq!(
            registration_difference(&Ok(other), Some(&reg.outcome)).as_deref(),
            Some("lk_iterations: host 4 device 5")
        );
        let mut other = host;
        other.degenerate = "Line".into();
        assert_eq!(
            registration_difference(&Ok(other), Some(&reg.outcome)).as_deref(),
            Some("degenerate: host Line device none")
        );
        let invalid: RegistrationOutcome =
            Err("InvalidOption { what: \"hypotheses must be at least 1\" }".into());
        assert_eq!(
            registration_difference(&invalid, Some(&run.registrations[&(1, 0)].outcome)),
            None
        );
        assert!(
            registration_difference(&invalid, Some(&run.registrations[&(1, 1)].outcome)).is_some()
        );
        assert!(registration_difference(&invalid, None).is_some());
    }
}
