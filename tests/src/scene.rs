//! The scene path in the harness: for every int8 model, the device renders
//! the harness frame ([`pcrnet_core::testing::scene::harness_frame`]),
//! runs the scene stages alone and then `Int8Model::locate` on it, and
//! prints what it found as words ([`pcrnet_core::testing::scene::describe`]);
//! the host computes the same ([`expected`]) and the words are compared
//! ([`difference`]). Not on the micro:bit (16 KiB of RAM, the frame alone is 77 KB).

use std::collections::BTreeMap;

use pcrnet_core::scene::{self, SceneOptions};
use pcrnet_core::testing::scene as harness;
use pcrnet_core::{Int8Model, Options};

use crate::vectors::{SCRATCH_LEN, error_text};

/// Sampling step of the harness's grid (the default of `SceneOptions::for_object`).
const STEP: usize = 4;

/// What `locate` found, as words, or the error's text.
pub type SceneResult = Result<String, String>;

/// What the device printed for one model's scene.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceScene {
    /// Instructions of the scene stages alone (`scene::segment`).
    pub segment: Option<u64>,
    /// Instructions of the whole `locate` call.
    pub locate: Option<u64>,
    /// Peak stack bytes of the `locate` call.
    pub stack: Option<usize>,
    /// The words, or the error.
    pub result: SceneResult,
}

/// Per model index.
pub type Scenes = BTreeMap<usize, DeviceScene>;

/// The host's result for `blob` (`None` for a blob that is not int8: the
/// device runs no scene for it).
pub fn expected(blob: &[u8]) -> Option<SceneResult> {
    let model = Int8Model::from_bytes(blob).ok()?;
    let (w, h) = (harness::HARNESS_WIDTH, harness::HARNESS_HEIGHT);
    let mut depth = vec![0u16; w * h];
    let mut template = vec![[0f32; 3]; 1024];
    let mut labels = vec![0u16; scene::labels_len(w, h, STEP)];
    let mut points = vec![[0f32; 3]; 512];
    let mut scratch = vec![0i8; SCRATCH_LEN];
    let mut run = || -> Result<String, pcrnet_core::Error> {
        harness::harness_frame(&model, &mut template, &mut depth)?;
        let image = harness::harness_image(&depth)?;
        let scene_options = SceneOptions::for_object(model.object_radius());
        scene::segment(&image, &scene_options, &mut labels)?;
        let located = model.locate(
            &image,
            &scene_options,
            harness::HARNESS_CANDIDATES,
            &Options::default(),
            &mut labels,
            &mut points,
            &mut scratch,
        )?;
        let mut words = String::new();
        harness::describe(&located, &mut words).expect("writing to a String");
        Ok(words)
    };
    Some(run().map_err(|e| error_text(&e)))
}

/// Parses a `model M scene ...` line's words after `scene` into `scenes`;
/// false if it is not one.
pub fn parse_line(m: &str, words: &[&str], scenes: &mut Scenes) -> bool {
    let Ok(m) = m.parse::<usize>() else {
        return false;
    };
    let entry = scenes.entry(m).or_insert(DeviceScene {
        segment: None,
        locate: None,
        stack: None,
        result: Err("no locate line".into()),
    });
    match words {
        ["segment", n] => match n.parse() {
            Ok(n) => entry.segment = Some(n),
            Err(_) => return false,
        },
        ["locate", instructions, stack, rest @ ..] => {
            let (Ok(i), Ok(s)) = (instructions.parse(), stack.parse()) else {
                return false;
            };
            entry.locate = Some(i);
            entry.stack = Some(s);
            entry.result = Ok(rest.join(" "));
        }
        ["error", error @ ..] if !error.is_empty() => entry.result = Err(error.join(" ")),
        _ => return false,
    }
    true
}

/// How the device's scene differs from the host's, if it does: the first
/// differing word and its place.
pub fn difference(host: &SceneResult, device: Option<&DeviceScene>) -> Option<String> {
    let Some(device) = device else {
        return Some("no scene output from the device".into());
    };
    match (host, &device.result) {
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
        let d = &scenes[&2];
        assert_eq!(
            (d.segment, d.locate, d.stack),
            (Some(1200), Some(900), Some(400))
        );
        let host: SceneResult = Ok("plane 3f800000 best 0".into());
        assert_eq!(difference(&host, Some(d)), None);
        let other: SceneResult = Ok("plane 3f800001 best 0".into());
        let why = difference(&other, Some(d)).unwrap();
        assert!(
            why.starts_with("word 1: host `3f800001` device `3f800000`"),
            "{why}"
        );
        assert!(difference(&host, None).is_some());
        assert!(!parse_line("x", &["segment", "1"], &mut scenes));
        assert!(!parse_line("1", &["locate", "a"], &mut scenes));
        assert!(parse_line("3", &["error", "InvalidFrame"], &mut scenes));
        assert_eq!(scenes[&3].result, Err("InvalidFrame".to_string()));
    }

    #[test]
    fn the_shipped_model_finds_its_object_in_the_harness_frame() {
        let blob = include_bytes!("../../models/embedded-default-int8.pcrn");
        let words = expected(blob).unwrap().unwrap();
        // The winner (`best CLUSTER`) is a candidate whose registration is
        // reliable and whose check against the frame passed (`... true true`).
        let (candidates, best) = words.rsplit_once(" best ").unwrap();
        let winner = candidates
            .split(" t ")
            .skip(1)
            .find(|t| t.split_whitespace().next() == Some(best))
            .unwrap_or_else(|| panic!("no candidate for cluster {best}: {words}"));
        assert!(winner.ends_with("true true"), "{winner}");
    }
}
