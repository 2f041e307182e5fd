//! The feature-space check in the harness: after each successful
//! `register` with `Options::default()`, the device runs
//! `Int8Model::feature_distance` on the same cloud and the registered pose,
//! and the host computes the same ([`expected`]); the distance's bits (or
//! the error) are compared ([`difference`]). The device runner
//! (`tests/firmware`) applies the same rule.

use std::collections::BTreeMap;

use pcrnet_core::pose::Pose;
use pcrnet_core::{Int8Model, Options};

use crate::vectors::{Case, RegistrationOutcome, SCRATCH_LEN, error_text};

/// A check's result: the distance's f32 bits, or the error's Debug text.
pub type FeatureResult = Result<u32, String>;

/// Checks per registration index.
pub type Features = BTreeMap<usize, FeatureResult>;

/// Whether a registration with `options` is followed by the check.
pub fn checked(options: &Options) -> bool {
    *options == Options::default()
}

/// What the host computes for the checks of a case, given its
/// registrations' outcomes (the host's own, in order).
pub fn expected(model: &[u8], case: &Case, registrations: &[RegistrationOutcome]) -> Features {
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    let mut scratch = vec![0i8; SCRATCH_LEN];
    let mut out = Features::new();
    for (k, (options, r)) in case.registrations.iter().zip(registrations).enumerate() {
        let Ok(r) = r else {
            continue;
        };
        if !checked(options) {
            continue;
        }
        let p = r.pose.map(f32::from_bits);
        let pose = Pose {
            rotation: [p[0], p[1], p[2], p[3]],
            translation: [p[4], p[5], p[6]],
        };
        let result = m
            .feature_distance(&case.cloud, &pose, &mut scratch)
            .map(f32::to_bits)
            .map_err(|e| error_text(&e));
        out.insert(k, result);
    }
    out
}

/// What the device printed for one check.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceFeature {
    /// The output, in the same form as the host's.
    pub result: FeatureResult,
    /// Instructions spent by the call.
    pub instructions: u64,
}

/// Parses a `case C feature K ...` line's words after `feature`:
/// `ok INSTRUCTIONS BITS` or `error INSTRUCTIONS ERROR...`.
pub fn parse_line(c: &str, words: &[&str]) -> Option<((usize, usize), DeviceFeature)> {
    let key = |k: &str| Some((c.parse().ok()?, k.parse().ok()?));
    match words {
        [k, "ok", instructions, bits] => Some((
            key(k)?,
            DeviceFeature {
                result: Ok(u32::from_str_radix(bits, 16).ok()?),
                instructions: instructions.parse().ok()?,
            },
        )),
        [k, "error", instructions, error @ ..] if !error.is_empty() => Some((
            key(k)?,
            DeviceFeature {
                result: Err(error.join(" ")),
                instructions: instructions.parse().ok()?,
            },
        )),
        _ => None,
    }
}

/// How a check differs between host and device, if it does.
pub fn difference(host: &FeatureResult, device: Option<&FeatureResult>) -> Option<String> {
    match device {
        None => Some("no output from the device".into()),
        Some(d) if d == host => None,
        Some(d) => Some(format!("host {host:x?} device {d:x?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_compares_feature_lines() {
        let words = ["1", "ok", "2500", "3c23d70a"];
        let ((c, k), d) = parse_line("4", &words).unwrap();
        assert_eq!((c, k, d.instructions), (4, 1, 2500));
        assert_eq!(d.result, Ok(0x3c23_d70a));
        assert_eq!(difference(&Ok(0x3c23_d70a), Some(&d.result)), None);
        assert!(difference(&Ok(0x3c23_d70b), Some(&d.result)).is_some());
        assert!(difference(&Ok(0x3c23_d70a), None).is_some());
        let err = ["0", "error", "10", "NonFiniteResult"];
        let (_, d) = parse_line("2", &err).unwrap();
        assert_eq!(d.result, Err("NonFiniteResult".to_string()));
        assert!(parse_line("1", &["0", "ok", "12"]).is_none());
        assert!(parse_line("x", &words).is_none());
    }
}
