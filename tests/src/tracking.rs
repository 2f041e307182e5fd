//! Tracking steps in the harness: after each successful `register`, the
//! device runs `Int8Model::track` with the same options from the starts
//! [`starts`] names, and with the default options also
//! `Int8Model::track_view` from the starts [`viewed_starts`] names and
//! [`pcrnet_core::testing::harness_viewpoint`] (not
//! on the micro:bit, whose flash the view code does not fit); the host
//! computes the same ([`expected`]); every field of the result and its
//! outcome are compared bit for bit ([`difference`]).

use std::collections::BTreeMap;

use pcrnet_core::pose::{self, Pose};
use pcrnet_core::{Int8Model, Options};

use crate::compare::parse_registration;
use crate::vectors::{Case, RegistrationBits, RegistrationOutcome, SCRATCH_LEN, error_text};

/// The poses a registration is tracked from: `held`, the registered pose
/// itself (a still object: the tracking step's cost), and with
/// `Options::default()` also `predicted`, its constant-velocity prediction
/// after the identity (`pose::predict(IDENTITY, pose)`, usually far off:
/// the fallback). The device runner (`tests/firmware`) applies the same rule.
pub fn starts(registered: &Pose, options: &Options) -> Vec<(&'static str, Pose)> {
    let mut out = vec![("held", *registered)];
    if *options == Options::default() {
        out.push(("predicted", pose::predict(&Pose::IDENTITY, registered)));
    }
    out
}

/// The starts of the `track_view` steps after a default registration:
/// `viewed-held` (the registered pose: a kept step's cost with the view
/// rendered) and `viewed` (the prediction after the identity, usually the
/// fallback). The device runner applies the same rule.
pub fn viewed_starts(registered: &Pose) -> [(&'static str, Pose); 2] {
    [
        ("viewed-held", *registered),
        ("viewed", pose::predict(&Pose::IDENTITY, registered)),
    ]
}

/// A tracking step's result: the registration's fields and the outcome's
/// name (`Kept`, `Recovered`, `Lost`), or the error's Debug text.
pub type TrackResult = Result<(RegistrationBits, String), String>;

/// Tracking steps per (registration index, start name).
pub type Tracks = BTreeMap<(usize, String), TrackResult>;

/// What the host computes for the tracking steps of a case, given its
/// registrations' outcomes (the host's own, in order); `view_side` the
/// board's view image side (`view::side_for`: none, no `viewed` step).
pub fn expected(
    model: &[u8],
    case: &Case,
    registrations: &[RegistrationOutcome],
    view_side: Option<usize>,
) -> Tracks {
    let m = Int8Model::from_bytes(model).expect("test models are valid");
    let mut scratch = vec![0i8; SCRATCH_LEN];
    let mut buffer = vec![0f32; pcrnet_core::scene::view::buffer_len(view_side.unwrap_or(0))];
    let viewpoint = pcrnet_core::testing::harness_viewpoint(&case.cloud);
    let mut out = Tracks::new();
    for (k, (options, r)) in case.registrations.iter().zip(registrations).enumerate() {
        let Ok(r) = r else {
            continue;
        };
        let p = r.pose.map(f32::from_bits);
        let registered = Pose {
            rotation: [p[0], p[1], p[2], p[3]],
            translation: [p[4], p[5], p[6]],
        };
        let as_result = |t: pcrnet_core::Result<pcrnet_core::Tracking>| {
            t.map(|t| {
                let outcome = format!("{:?}", t.outcome);
                (RegistrationBits::from(&t.registration), outcome)
            })
            .map_err(|e| error_text(&e))
        };
        for (name, start) in starts(&registered, options) {
            let result = as_result(m.track(&case.cloud, &start, options, &mut scratch));
            out.insert((k, name.to_string()), result);
        }
        if view_side.is_some() && *options == Options::default() {
            for (name, start) in viewed_starts(&registered) {
                let result = as_result(m.track_view(
                    &case.cloud,
                    &start,
                    viewpoint,
                    options,
                    &mut scratch,
                    &mut buffer,
                ));
                out.insert((k, name.to_string()), result);
            }
        }
    }
    out
}

/// What the device printed for one tracking step.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceTrack {
    /// The outputs, in the same form as the host's.
    pub result: TrackResult,
    /// Instructions spent by the call.
    pub instructions: u64,
    /// Peak stack bytes during the call.
    pub stack: usize,
}

/// Parses a `case C track K START ...` line's words after `track`:
/// `((case, k, start), step)`, or `None` if it is not one.
pub fn parse_line(c: &str, words: &[&str]) -> Option<((usize, usize, String), DeviceTrack)> {
    let (c, (k, start, rest)) = match words {
        [k, start, rest @ ..] => (c.parse().ok()?, (k.parse().ok()?, start.to_string(), rest)),
        _ => return None,
    };
    let step = match rest {
        ["ok", fields @ .., outcome] => {
            let r = parse_registration(fields)?;
            DeviceTrack {
                result: r.outcome.map(|bits| (bits, outcome.to_string())),
                instructions: r.instructions,
                stack: r.stack,
            }
        }
        ["error", instructions, stack, error @ ..] if !error.is_empty() => DeviceTrack {
            result: Err(error.join(" ")),
            instructions: instructions.parse().ok()?,
            stack: stack.parse().ok()?,
        },
        _ => return None,
    };
    Some(((c, k, start), step))
}

/// How a tracking step differs between host and device, if it does.
pub fn difference(host: &TrackResult, device: Option<&TrackResult>) -> Option<String> {
    match (host, device) {
        (_, None) => Some("no output from the device".into()),
        (Ok((h, ho)), Some(Ok((d, dout)))) => {
            crate::compare::registration_difference(&Ok(h.clone()), Some(&Ok(d.clone())))
                .or_else(|| (ho != dout).then(|| format!("outcome: host {ho} device {dout}")))
        }
        (h, Some(d)) if h == d => None,
        (h, Some(d)) => Some(format!("host {h:?} device {d:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_compares_tracking_lines() {
        let fields = "3f800000 0 0 0 0 0 0 3c23d70a 3c23d70a 3f800000 0 3c23d70a 3c23d70a 0 0 0 3 0 0 none true none none";
        let ok = format!("case 4 track 1 held ok 900 500 {fields} Kept");
        let words: Vec<&str> = ok.split_whitespace().collect();
        let ((c, k, start), step) = parse_line(words[1], &words[3..]).unwrap();
        assert_eq!((c, k, start.as_str()), (4, 1, "held"));
        assert_eq!((step.instructions, step.stack), (900, 500));
        let (bits, outcome) = step.result.clone().unwrap();
        assert_eq!((bits.icp_iterations, outcome.as_str()), (3, "Kept"));
        assert_eq!(difference(&step.result, Some(&step.result)), None);
        let recovered = Ok((bits.clone(), "Recovered".to_string()));
        assert_eq!(
            difference(&recovered, Some(&step.result)).as_deref(),
            Some("outcome: host Recovered device Kept")
        );
        let mut moved = bits;
        moved.pose[4] ^= 1;
        assert!(difference(&Ok((moved, "Kept".into())), Some(&step.result)).is_some());
        assert!(difference(&step.result, None).is_some());

        let err = "case 2 track 0 predicted error 10 20 InvalidPose";
        let words: Vec<&str> = err.split_whitespace().collect();
        let (key, step) = parse_line(words[1], &words[3..]).unwrap();
        assert_eq!(key, (2, 0, "predicted".to_string()));
        assert_eq!(step.result, Err("InvalidPose".to_string()));
        let broken = ["0", "held", "ok", "12"];
        assert!(parse_line("1", &broken).is_none());
    }
}
