//! The viewed registration in the harness: after each successful
//! `register` with `Options::default()`, the device runs
//! `Int8Model::register_view` on the same cloud from
//! [`pcrnet_core::testing::harness_viewpoint`] (the registration with its
//! turned starts judged by the view, and its check against it), and the
//! host computes the same ([`expected`]); every field of the registration,
//! the check's counts and the verdict (or the error) are compared
//! ([`difference`]). The device runner (`tests/firmware`) applies the same
//! rule.

use std::collections::BTreeMap;

use pcrnet_core::testing::{HARNESS_VIEW_SIDE, harness_viewpoint};
use pcrnet_core::{Int8Model, Options};

use crate::compare::parse_registration;
use crate::vectors::{Case, RegistrationBits, RegistrationOutcome, SCRATCH_LEN, error_text};

/// A viewed registration's result: the registration's fields and `[supported,
/// violations, occluded, unobserved, passed, reliable]`, or the error's
/// Debug text.
pub type ViewResult = Result<(RegistrationBits, [u32; 6]), String>;

/// Viewed registrations per registration index.
pub type Views = BTreeMap<usize, ViewResult>;

/// What the host computes for a case, given its registrations' outcomes
/// (the host's own, in order: a viewed registration follows each
/// successful one with the default options); `side` is the board's image
/// side ([`side_for`]: none, no viewed registrations).
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
    let mut scratch = vec![0i8; SCRATCH_LEN];
    let viewpoint = harness_viewpoint(&case.cloud);
    let mut out = Views::new();
    for (k, (options, r)) in case.registrations.iter().zip(registrations).enumerate() {
        if r.is_err() || *options != Options::default() {
            continue;
        }
        let result = m
            .register_view(&case.cloud, viewpoint, options, &mut scratch, &mut buffer)
            .map(|v| {
                let c = v.view;
                (
                    RegistrationBits::from(&v.registration),
                    [
                        c.supported,
                        c.violations,
                        c.occluded,
                        c.unobserved,
                        u32::from(c.passed),
                        u32::from(v.reliable),
                    ],
                )
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

/// What the device printed for one viewed registration.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceView {
    /// The output, in the same form as the host's.
    pub result: ViewResult,
    /// Instructions spent by the call.
    pub instructions: u64,
    /// Peak stack bytes during the call.
    pub stack: usize,
}

/// Parses a `case C view K ...` line's words after `view`: `ok
/// INSTRUCTIONS STACK` and a registration's fields, then `S V O U P R`; or
/// `error INSTRUCTIONS STACK ERROR...`.
pub fn parse_line(c: &str, words: &[&str]) -> Option<((usize, usize), DeviceView)> {
    let key = |k: &str| Some((c.parse().ok()?, k.parse().ok()?));
    match words {
        [k, "ok", rest @ ..] if rest.len() > 6 => {
            let (fields, counts) = rest.split_at(rest.len() - 6);
            let r = parse_registration(fields)?;
            let mut v = [0u32; 6];
            for (slot, word) in v.iter_mut().zip(counts) {
                *slot = word.parse().ok()?;
            }
            Some((
                key(k)?,
                DeviceView {
                    result: r.outcome.map(|bits| (bits, v)),
                    instructions: r.instructions,
                    stack: r.stack,
                },
            ))
        }
        [k, "error", instructions, stack, error @ ..] if !error.is_empty() => Some((
            key(k)?,
            DeviceView {
                result: Err(error.join(" ")),
                instructions: instructions.parse().ok()?,
                stack: stack.parse().ok()?,
            },
        )),
        _ => None,
    }
}

/// How a viewed registration differs between host and device, if it does.
pub fn difference(host: &ViewResult, device: Option<&ViewResult>) -> Option<String> {
    match (host, device) {
        (_, None) => Some("no output from the device".into()),
        (Ok((h, hc)), Some(Ok((d, dc)))) => {
            crate::compare::registration_difference(&Ok(h.clone()), Some(&Ok(d.clone())))
                .or_else(|| (hc != dc).then(|| format!("view counts: host {hc:?} device {dc:?}")))
        }
        (h, Some(d)) if h == d => None,
        (h, Some(d)) => Some(format!("host {h:?} device {d:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_compares_view_lines() {
        let fields = "3f800000 0 0 0 0 0 0 3c23d70a 3c23d70a 3f800000 0 3c23d70a 3c23d70a 0 0 0 3 0 0 none true none none";
        let ok = format!("case 4 view 1 ok 2500 600 {fields} 120 3 200 0 1 1");
        let words: Vec<&str> = ok.split_whitespace().collect();
        let ((c, k), d) = parse_line(words[1], &words[3..]).unwrap();
        assert_eq!((c, k, d.instructions, d.stack), (4, 1, 2500, 600));
        let (bits, counts) = d.result.clone().unwrap();
        assert_eq!((bits.icp_iterations, counts), (3, [120, 3, 200, 0, 1, 1]));
        assert_eq!(difference(&d.result, Some(&d.result)), None);
        let other = Ok((bits.clone(), [120, 4, 200, 0, 1, 1]));
        assert!(
            difference(&other, Some(&d.result))
                .unwrap()
                .starts_with("view counts")
        );
        let mut moved = bits;
        moved.pose[4] ^= 1;
        assert!(difference(&Ok((moved, counts)), Some(&d.result)).is_some());
        assert!(difference(&d.result, None).is_some());
        let err = "case 2 view 0 error 10 20 InvalidOption { what: \"x\" }";
        let words: Vec<&str> = err.split_whitespace().collect();
        let (key, d) = parse_line(words[1], &words[3..]).unwrap();
        assert_eq!(key, (2, 0));
        assert!(d.result.is_err());
        assert!(parse_line("1", &["0", "ok", "12", "1", "2"]).is_none());
        assert!(parse_line("x", &words[3..]).is_none());
    }

    /// The shipped model's demo source seen from the harness's viewpoint:
    /// the viewed registration counts every stored template point once,
    /// its check is the pose's (`check_view`), and its verdict is both.
    #[test]
    fn the_harness_viewed_registration_is_consistent() {
        let blob = include_bytes!("../../models/embedded-default-int8.pcrn");
        let m = Int8Model::from_bytes(blob).unwrap();
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let source =
            crate::vectors::read_cloud(&root.join("models/embedded-default-source.f32")).unwrap();
        let mut scratch = vec![0i8; SCRATCH_LEN];
        let mut buffer = vec![0f32; pcrnet_core::scene::view::buffer_len(HARNESS_VIEW_SIDE)];
        let at = harness_viewpoint(&source);
        let v = m
            .register_view(&source, at, &Options::default(), &mut scratch, &mut buffer)
            .unwrap();
        let c = v.view;
        let total = c.supported + c.violations + c.occluded + c.unobserved + c.outside;
        assert_eq!(total as usize, m.template().len(), "{c:?}");
        let again = m
            .check_view(&source, at, &v.registration.pose, &mut buffer)
            .unwrap();
        assert_eq!(again, c);
        assert_eq!(v.reliable, v.registration.reliable && c.passed);
    }
}
