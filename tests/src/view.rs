//! The view check in the harness: after each successful `register` with
//! `Options::default()`, the device runs `Int8Model::check_view` on the
//! same cloud and the registered pose, from
//! [`pcrnet_core::testing::harness_viewpoint`], and the host computes the
//! same ([`expected`]); the counts and the verdict (or the error) are
//! compared ([`difference`]). The device runner (`tests/firmware`)
//! applies the same rule.

use std::collections::BTreeMap;

use pcrnet_core::pose::Pose;
use pcrnet_core::testing::{HARNESS_VIEW_SIDE, harness_viewpoint};
use pcrnet_core::{Int8Model, Options};

use crate::vectors::{Case, RegistrationOutcome, error_text};

/// A check's result: `[supported, violations, occluded, unobserved,
/// passed]`, or the error's Debug text.
pub type ViewResult = Result<[u32; 5], String>;

/// Checks per registration index.
pub type Views = BTreeMap<usize, ViewResult>;

/// What the host computes for the checks of a case, given its
/// registrations' outcomes (the host's own, in order); `side` is the
/// board's image side ([`side_for`]: none, no checks).
pub fn expected(
    model: &[u8],
    case: &Case,
    registrations: &[RegistrationOutcome],
    side: Option<usize>,
) -> Views {
    let Some(side) = side else {
        return Views::new();
    };
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    let mut buffer = vec![0f32; pcrnet_core::scene::view::buffer_len(side)];
    let viewpoint = harness_viewpoint(&case.cloud);
    let mut out = Views::new();
    for (k, (options, r)) in case.registrations.iter().zip(registrations).enumerate() {
        let Ok(r) = r else {
            continue;
        };
        if *options != Options::default() {
            continue;
        }
        let p = r.pose.map(f32::from_bits);
        let pose = Pose {
            rotation: [p[0], p[1], p[2], p[3]],
            translation: [p[4], p[5], p[6]],
        };
        let result = m
            .check_view(&case.cloud, viewpoint, &pose, &mut buffer)
            .map(|v| {
                [
                    v.supported,
                    v.violations,
                    v.occluded,
                    v.unobserved,
                    u32::from(v.passed),
                ]
            })
            .map_err(|e| error_text(&e));
        out.insert(k, result);
    }
    out
}

/// The image side the harness uses on `machine`, or `None` where the
/// runner leaves the check out (the micro:bit: its code does not fit the
/// flash beside the harness's vectors).
pub fn side_for(machine: &str) -> Option<usize> {
    (machine != "microbit").then_some(HARNESS_VIEW_SIDE)
}

/// What the device printed for one check.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceView {
    /// The output, in the same form as the host's.
    pub result: ViewResult,
    /// Instructions spent by the call.
    pub instructions: u64,
}

/// Parses a `case C view K ...` line's words after `view`: `ok
/// INSTRUCTIONS S V O U P` or `error INSTRUCTIONS ERROR...`.
pub fn parse_line(c: &str, words: &[&str]) -> Option<((usize, usize), DeviceView)> {
    let key = |k: &str| Some((c.parse().ok()?, k.parse().ok()?));
    match words {
        [k, "ok", instructions, counts @ ..] if counts.len() == 5 => {
            let mut v = [0u32; 5];
            for (slot, word) in v.iter_mut().zip(counts) {
                *slot = word.parse().ok()?;
            }
            Some((
                key(k)?,
                DeviceView {
                    result: Ok(v),
                    instructions: instructions.parse().ok()?,
                },
            ))
        }
        [k, "error", instructions, error @ ..] if !error.is_empty() => Some((
            key(k)?,
            DeviceView {
                result: Err(error.join(" ")),
                instructions: instructions.parse().ok()?,
            },
        )),
        _ => None,
    }
}

/// How a check differs between host and device, if it does.
pub fn difference(host: &ViewResult, device: Option<&ViewResult>) -> Option<String> {
    match device {
        None => Some("no output from the device".into()),
        Some(d) if d == host => None,
        Some(d) => Some(format!("host {host:?} device {d:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_compares_view_lines() {
        let words = ["1", "ok", "2500", "120", "3", "200", "0", "1"];
        let ((c, k), d) = parse_line("4", &words).unwrap();
        assert_eq!((c, k, d.instructions), (4, 1, 2500));
        assert_eq!(d.result, Ok([120, 3, 200, 0, 1]));
        assert_eq!(difference(&Ok([120, 3, 200, 0, 1]), Some(&d.result)), None);
        assert!(difference(&Ok([120, 4, 200, 0, 1]), Some(&d.result)).is_some());
        assert!(difference(&d.result, None).is_some());
        let err = ["0", "error", "10", "InvalidOption", "{", "what:", "x", "}"];
        let (_, d) = parse_line("2", &err).unwrap();
        assert!(d.result.is_err());
        assert!(parse_line("1", &["0", "ok", "12", "1", "2"]).is_none());
        assert!(parse_line("x", &words).is_none());
    }

    /// The shipped model's demo source registered by default: seen from
    /// the harness's viewpoint, the check runs and counts every stored
    /// template point once.
    #[test]
    fn the_harness_view_check_counts_every_template_point() {
        let blob = include_bytes!("../../models/embedded-default-int8.pcrn");
        let m = Int8Model::from_bytes(blob).unwrap();
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let source =
            crate::vectors::read_cloud(&root.join("models/embedded-default-source.f32")).unwrap();
        let mut scratch = vec![0i8; crate::vectors::SCRATCH_LEN];
        let r = m
            .register(&source, &Options::default(), &mut scratch)
            .unwrap();
        let mut buffer = vec![0f32; pcrnet_core::scene::view::buffer_len(HARNESS_VIEW_SIDE)];
        let v = m
            .check_view(&source, harness_viewpoint(&source), &r.pose, &mut buffer)
            .unwrap();
        let total = v.supported + v.violations + v.occluded + v.unobserved;
        assert_eq!(total as usize, m.template().len(), "{v:?}");
        assert!(v.supported > 0, "{v:?}");
    }
}
