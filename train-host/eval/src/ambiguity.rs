//! The `ambiguity` experiment (issue 36, item 4): does the device pipeline
//! say when a pose is one of several that fit? The shipped model's default
//! registration on shapes with a symmetry (generated cylinders, cones and
//! boxes; ModelNet10 tables and night stands) and on shapes without a
//! rotational one (ModelNet10 chairs, toilets, sofas, beds: at most a
//! mirror symmetry, which no rotation reaches, though beds come close to a
//! half turn), each pose scored plainly and up to the shape's symmetry
//! (ADD-S), with what it reported.

use anyhow::Context as _;

use super::pairs::{PairSetSpec, Shapes};
use super::trust::{SHIPPED_INT8, device};
use super::{GOOD_BELOW_DEG, MethodScore, PairScore};
use crate::report::{Context, POINTS, Recorder, Report, Table, folder, pair_set, pair_spec};
use pcrnet_train::data::PairConfig;

/// Noise sigma of every set (the `trust` experiment's).
const SIGMA: f32 = 0.01;

/// A pose is right up to the shape's symmetry when its ADD-S is at most
/// this share of the template's diameter (about what 5 degrees of rotation
/// costs a point on the template's bounding sphere: 0.044).
pub const SYMMETRIC_OK: f64 = 0.05;

/// The shapes with a rotational symmetry in ModelNet10's classes.
const SYMMETRIC_CLASSES: [&str; 2] = ["table", "night_stand"];

/// ModelNet10's classes with at most a mirror symmetry.
const ASYMMETRIC_CLASSES: [&str; 4] = ["chair", "toilet", "sofa", "bed"];

/// Runs the experiment (see the module docs).
pub fn ambiguity(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let blob = std::fs::read(SHIPPED_INT8).with_context(|| {
        format!("reading {SHIPPED_INT8} (run the experiment from the repository root)")
    })?;
    let model = Some(("embedded-default-int8", blob.as_slice()));
    let mut rec = Recorder::new(ctx, "ambiguity");
    let noisy = PairConfig {
        noise: Some([SIGMA, SIGMA]),
        ..PairConfig::default()
    };
    // Sources sampled apart from the template, as a sensor sees a shape.
    let resampled = |spec: PairSetSpec| PairSetSpec {
        resample: true,
        ..spec
    };
    let sets = [
        (
            "generated cylinders, cones, boxes",
            "ambiguity-generated",
            resampled(pair_spec(
                ctx,
                Shapes::Symmetric { count: ctx.pairs },
                POINTS,
                noisy,
            )),
        ),
        (
            "ModelNet10 tables, night stands",
            "ambiguity-mn10-symmetric",
            resampled(folder(ctx, "ModelNet10", Some(&SYMMETRIC_CLASSES), noisy)),
        ),
        (
            "ModelNet10 chairs, toilets, sofas, beds",
            "ambiguity-mn10-asymmetric",
            resampled(folder(ctx, "ModelNet10", Some(&ASYMMETRIC_CLASSES), noisy)),
        ),
    ];
    let recommended = pcrnet_core::Options::default().hypotheses;
    let mut labels = Vec::new();
    for (set, file, spec) in sets {
        let pairs = pair_set(ctx, file, spec)?;
        rec.score(set, device(recommended), model, &pairs, true)?;
        labels.push(pairs.into_iter().map(|p| p.label).collect::<Vec<_>>());
    }
    let tables = vec![table(&rec.raw), by_class(&rec.raw, &labels)];
    rec.finish(
        "Saying when a pose is ambiguous",
        vec![
            format!(
                "The shipped model (`{SHIPPED_INT8}`), its default device pipeline (K={recommended}), {} pairs per set, sources resampled apart from the template with Gaussian noise sigma {SIGMA}, Euler angles U[-45°, 45°], translation U[-1, 1], {POINTS} points.",
                ctx.pairs
            ),
            "Generated: closed cylinders and cones (free about their axis) and boxes 1 : 0.6 : 0.3 (three half turns fit as well), unstretched, in turn. ModelNet10 tables and night stands hold round and square ones; chairs, toilets, sofas and beds have at most a mirror symmetry, which no rotation reaches, but many beds and some sofas come close to a half-turn symmetry (a box with a low head board).".into(),
            format!(
                "Ambiguous: the registration reported a free rotation axis (stiffness below {}) or a turn to another start fitting within {} x its plane residual (`pcrnet_core::ambiguity`). Explained: the turn leads within {GOOD_BELOW_DEG}° of the truth, or the error rotation turns about the free axis (within about 18°). Up to symmetry: ADD-S (the template moved by the estimate and by the truth, mean closest-point distance) at most {SYMMETRIC_OK} of the template's diameter.",
                pcrnet_core::ambiguity::FREE_AXIS_STIFFNESS,
                pcrnet_core::ambiguity::TURN_RESIDUAL_RATIO
            ),
        ],
        tables,
        started,
    )
}

/// One row per set: plain and symmetry-aware success, the reliable poses
/// that are wrong, and how many of those the ambiguity reports explain.
fn table(raw: &[(String, MethodScore)]) -> Table {
    Table {
        caption: format!(
            "Plain success ({GOOD_BELOW_DEG}°), success up to the shape's symmetry (ADD-S <= {SYMMETRIC_OK} of the diameter), and the reliable poses more than {GOOD_BELOW_DEG}° off: how many were reported ambiguous, and how many of those reports name the turn or axis that explains the error"
        ),
        header: [
            "test set",
            "pairs",
            "ok (5°)",
            "ok up to symmetry",
            "reliable",
            "reliable, > 5° off",
            "of those ambiguous",
            "of those explained",
            "ambiguous (all pairs)",
            "ambiguous, < 5° off",
            "of those by a turn alone: rival / pose residual",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect(),
        rows: raw.iter().map(|(set, s)| row(set, s)).collect(),
    }
}

/// `k (p%)` of `of`, or `-` for none.
fn share(k: usize, of: usize) -> String {
    if of == 0 {
        "-".to_string()
    } else {
        format!("{k} ({:.1}%)", 100.0 * k as f64 / of as f64)
    }
}

/// Reliable poses more than the success angle off.
fn wrong_reliable<'a>(pairs: impl IntoIterator<Item = &'a PairScore>) -> Vec<&'a PairScore> {
    pairs
        .into_iter()
        .filter(|p| p.reliable == Some(true) && p.rot_deg > GOOD_BELOW_DEG)
        .collect()
}

/// One row per class of every set: how often a pose of it was reported
/// ambiguous, and its reliable poses that are wrong.
fn by_class(raw: &[(String, MethodScore)], labels: &[Vec<String>]) -> Table {
    let mut classes: Vec<(String, Vec<&PairScore>)> = Vec::new();
    for ((_, s), labels) in raw.iter().zip(labels) {
        for (p, label) in s.pairs.iter().zip(labels) {
            match classes.iter_mut().find(|(c, _)| c == label) {
                Some((_, v)) => v.push(p),
                None => classes.push((label.clone(), vec![p])),
            }
        }
    }
    Table {
        caption: "Per class: poses reported ambiguous, and the reliable poses more than 5° off with how many of those were reported ambiguous".into(),
        header: [
            "class",
            "pairs",
            "ambiguous",
            "reliable, > 5° off",
            "of those ambiguous",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect(),
        rows: classes
            .iter()
            .map(|(class, pairs)| {
                let wrong = wrong_reliable(pairs.iter().copied());
                let flagged = wrong.iter().filter(|p| p.ambiguous == Some(true)).count();
                vec![
                    class.clone(),
                    pairs.len().to_string(),
                    share(
                        pairs.iter().filter(|p| p.ambiguous == Some(true)).count(),
                        pairs.len(),
                    ),
                    share(wrong.len(), pairs.len()),
                    share(flagged, wrong.len()),
                ]
            })
            .collect(),
    }
}

fn row(set: &str, s: &MethodScore) -> Vec<String> {
    let n = s.pairs.len();
    let count = |f: &dyn Fn(&PairScore) -> bool| s.pairs.iter().filter(|p| f(p)).count();
    let wrong_reliable = wrong_reliable(&s.pairs);
    let flagged = wrong_reliable
        .iter()
        .filter(|p| p.ambiguous == Some(true))
        .count();
    let explained = wrong_reliable
        .iter()
        .filter(|p| p.explained == Some(true))
        .count();
    vec![
        set.to_string(),
        n.to_string(),
        share(count(&|p| p.rot_deg <= GOOD_BELOW_DEG), n),
        share(
            count(&|p| p.symmetric_error.is_some_and(|e| e <= SYMMETRIC_OK)),
            n,
        ),
        share(count(&|p| p.reliable == Some(true)), n),
        share(wrong_reliable.len(), n),
        share(flagged, wrong_reliable.len()),
        share(explained, flagged),
        share(count(&|p| p.ambiguous == Some(true)), n),
        share(
            count(&|p| p.ambiguous == Some(true) && p.rot_deg <= GOOD_BELOW_DEG),
            n,
        ),
        turn_ratios(
            s.pairs
                .iter()
                .filter(|p| p.rot_deg <= GOOD_BELOW_DEG)
                .filter_map(|p| p.turn_only_ratio),
        ),
    ]
}

/// How many ratios, and their range: `k (lo-hi)`, or `-` for none.
fn turn_ratios(ratios: impl Iterator<Item = f64>) -> String {
    let v: Vec<f64> = ratios.collect();
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if v.is_empty() {
        "-".to_string()
    } else {
        format!("{} ({lo:.2}-{hi:.2})", v.len())
    }
}
