//! The scene path in the harness: for every int8 model, the device renders
//! the harness frame ([`pcrnet_core::testing::scene::harness_frame`]),
//! runs the scene stages alone and then `Int8Model::locate` on it twice,
//! with the network's hypotheses (`locate`) and with the template's up axis
//! given (`sweep`), and prints what it found as words
//! ([`pcrnet_core::testing::scene::describe`]); the host computes the same
//! ([`expected`]) and the words are compared ([`difference`]). Not on the
//! micro:bit (16 KiB of RAM; the frame alone is 77 KB).

use std::collections::BTreeMap;

use pcrnet_core::scene::{self, SceneOptions};
use pcrnet_core::testing::scene as harness;
use pcrnet_core::{Int8Model, Options};

use crate::vectors::{SCRATCH_LEN, error_text};

/// Sampling step of the harness's grid (the default of `SceneOptions::for_object`).
const STEP: usize = 4;

/// The runs per model, in the device's order: the last follows the frame
/// from the sweep's result ([`pcrnet_core::testing::scene::follow_start`]).
pub const RUNS: [&str; 3] = ["locate", "sweep", "follow"];

/// What a run found, as words, or the error's text.
pub type SceneResult = Result<String, String>;

/// What the device printed for one run.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceRun {
    /// Instructions of the `locate` call.
    pub instructions: u64,
    /// Its peak stack bytes.
    pub stack: usize,
    /// The words, or the error.
    pub result: SceneResult,
}

/// What the device printed for one model's scene.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DeviceScene {
    /// Instructions of the scene stages alone (`scene::segment`).
    pub segment: Option<u64>,
    /// Each run by name.
    pub runs: BTreeMap<String, DeviceRun>,
    /// The frame could not be made or segmented.
    pub error: Option<String>,
}

/// Per model index.
pub type Scenes = BTreeMap<usize, DeviceScene>;

/// The host's results for `blob`, one per [`RUNS`] (`None` for a blob that
/// is not int8: the device runs no scene for it); a frame that cannot be
/// made gives one `Err` per run.
pub fn expected(blob: &[u8]) -> Option<Vec<SceneResult>> {
    let model = Int8Model::from_bytes(blob).ok()?;
    let (w, h) = (harness::HARNESS_WIDTH, harness::HARNESS_HEIGHT);
    let mut depth = vec![0u16; w * h];
    let mut template = vec![[0f32; 3]; 1024];
    let mut labels = vec![0u16; scene::labels_len(w, h, STEP)];
    let mut points = vec![[0f32; 3]; 512];
    let mut scratch = vec![0i8; SCRATCH_LEN];
    let frame = harness::harness_frame(&model, &mut template, &mut depth)
        .and_then(|_| harness::harness_image(&depth));
    let image = match frame {
        Ok(image) => image,
        Err(e) => return Some(vec![Err(error_text(&e)); RUNS.len()]),
    };
    let plain = SceneOptions::for_object(model.object_radius());
    if let Err(e) = scene::segment(&image, &plain, &mut labels) {
        return Some(vec![Err(error_text(&e)); RUNS.len()]);
    }
    let swept = SceneOptions {
        up: Some(harness::HARNESS_UP),
        ..plain
    };
    let words = |located: &pcrnet_core::locate::Located| {
        let mut words = String::new();
        harness::describe(located, &mut words).expect("writing to a String");
        words
    };
    let mut results = Vec::new();
    let mut last = (pcrnet_core::Pose::IDENTITY, None);
    for (i, o) in [plain, swept].iter().enumerate() {
        let located = model.locate(
            &image,
            o,
            harness::HARNESS_CANDIDATES,
            &Options::default(),
            &mut labels,
            &mut points,
            &mut scratch,
        );
        if i == 1
            && let Ok(l) = &located
        {
            last = harness::follow_start(l);
        }
        results.push(located.map(|l| words(&l)).map_err(|e| error_text(&e)));
    }
    let followed = model.follow(
        &image,
        &plain,
        &last.0,
        last.1,
        &Options::default(),
        &mut labels,
        &mut points,
        &mut scratch,
    );
    results.push(followed.map(|l| words(&l)).map_err(|e| error_text(&e)));
    Some(results)
}

/// Parses a `model M scene ...` line's words after `scene` into `scenes`;
/// false if it is not one.
pub fn parse_line(m: &str, words: &[&str], scenes: &mut Scenes) -> bool {
    let Ok(m) = m.parse::<usize>() else {
        return false;
    };
    let entry = scenes.entry(m).or_default();
    match words {
        ["segment", n] => match n.parse() {
            Ok(n) => entry.segment = Some(n),
            Err(_) => return false,
        },
        ["error", error @ ..] if !error.is_empty() => entry.error = Some(error.join(" ")),
        [run, "error", error @ ..] if RUNS.contains(run) && !error.is_empty() => {
            entry.runs.insert(
                run.to_string(),
                DeviceRun {
                    instructions: 0,
                    stack: 0,
                    result: Err(error.join(" ")),
                },
            );
        }
        [run, instructions, stack, rest @ ..] if RUNS.contains(run) => {
            let (Ok(i), Ok(s)) = (instructions.parse(), stack.parse()) else {
                return false;
            };
            entry.runs.insert(
                run.to_string(),
                DeviceRun {
                    instructions: i,
                    stack: s,
                    result: Ok(rest.join(" ")),
                },
            );
        }
        _ => return false,
    }
    true
}

/// How the device's scene differs from the host's, if it does: the first
/// run that differs, its first differing word and its place.
pub fn difference(host: &[SceneResult], device: Option<&DeviceScene>) -> Option<String> {
    let Some(device) = device else {
        return Some("no scene output from the device".into());
    };
    for (name, h) in RUNS.iter().zip(host) {
        let d = match (&device.error, device.runs.get(*name)) {
            (_, Some(run)) => run.result.clone(),
            (Some(e), None) => Err(e.clone()),
            (None, None) => return Some(format!("{name}: no output from the device")),
        };
        if let Some(why) = words_difference(h, &d) {
            return Some(format!("{name}: {why}"));
        }
    }
    None
}

fn words_difference(host: &SceneResult, device: &SceneResult) -> Option<String> {
    match (host, device) {
        (Ok(h), Ok(d)) if h == d => None,
        (Ok(h), Ok(d)) => {
            let (hw, dw): (Vec<&str>, Vec<&str>) = (
                h.split_whitespace().collect(),
                d.split_whitespace().collect(),
            );
            let at = hw
                .iter()
                .zip(&dw)
                .position(|(a, b)| a != b)
                .unwrap_or(hw.len().min(dw.len()));
            Some(format!(
                "word {at}: host `{}` device `{}` (host: {h})",
                hw.get(at).unwrap_or(&"(end)"),
                dw.get(at).unwrap_or(&"(end)")
            ))
        }
        (h, d) if h == d => None,
        (h, d) => Some(format!("host {h:?} device {d:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_compares_scene_lines() {
        let mut scenes = Scenes::new();
        assert!(parse_line("2", &["segment", "1200"], &mut scenes));
        let words = ["locate", "900", "400", "plane", "3f800000", "best", "0"];
        assert!(parse_line("2", &words, &mut scenes));
        assert!(parse_line(
            "2",
            &["sweep", "error", "InvalidOption"],
            &mut scenes
        ));
        let d = &scenes[&2];
        assert_eq!(d.segment, Some(1200));
        assert_eq!(
            (d.runs["locate"].instructions, d.runs["locate"].stack),
            (900, 400)
        );
        let host: Vec<SceneResult> = vec![
            Ok("plane 3f800000 best 0".into()),
            Err("InvalidOption".into()),
        ];
        assert_eq!(difference(&host, Some(d)), None);
        let other: Vec<SceneResult> = vec![Ok("plane 3f800001 best 0".into()), host[1].clone()];
        let why = difference(&other, Some(d)).unwrap();
        assert!(
            why.starts_with("locate: word 1: host `3f800001` device `3f800000`"),
            "{why}"
        );
        assert!(difference(&host, None).is_some());
        assert!(!parse_line("x", &["segment", "1"], &mut scenes));
        assert!(!parse_line("1", &["locate", "a"], &mut scenes));
        assert!(!parse_line("1", &["other", "1", "2"], &mut scenes));
        assert!(parse_line("3", &["error", "InvalidFrame"], &mut scenes));
        let failed = vec![Err("InvalidFrame".to_string()); 2];
        assert_eq!(difference(&failed, scenes.get(&3)), None);
    }

    /// The winner (`best CLUSTER`) of `words` is a candidate whose
    /// registration is reliable and whose check passed (`... true true`,
    /// then the two words of its ambiguity).
    fn winner_is_reliable(words: &str) -> bool {
        let Some((candidates, best)) = words.rsplit_once(" best ") else {
            return false;
        };
        candidates
            .split(" t ")
            .skip(1)
            .find(|t| t.split_whitespace().next() == Some(best))
            .is_some_and(|t| t.split_whitespace().rev().nth(2) == Some("true"))
    }

    #[test]
    fn the_sweep_finds_the_shipped_object_in_the_harness_frame() {
        let blob = include_bytes!("../../models/embedded-default-int8.pcrn");
        let results = expected(blob).unwrap();
        let sweep = results[1].as_ref().unwrap();
        assert!(winner_is_reliable(sweep), "{sweep}");
        // Followed from the sweep's pose on the same frame: found again.
        let follow = results[2].as_ref().unwrap();
        assert!(winner_is_reliable(follow), "{follow}");
    }
}
