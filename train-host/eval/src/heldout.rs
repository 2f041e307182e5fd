//! The `heldout` experiment (issue 11, item 6): does more varied training
//! data help on classes no model saw? The generalisation experiment's
//! five-class i-PCRNet beside the same recipe with every other shape of
//! the data root added (the ModelNet40 airplanes and generated shapes),
//! trained for as many steps, and with identity pairs (5% of pairs at zero
//! motion), on the five held-out ModelNet10 classes and on the five seen
//! ones.

use super::MethodScore;
use super::methods::{Method, MethodKind};
use super::recipes::HELDOUT_RECIPES;
use super::trust::{device, table};
use crate::report::{Context, Recorder, Report, SEEN, UNSEEN, folder, pair_set, success_chart};
use pcrnet_train::data::PairConfig;

/// Noise sigma of both sets (as the `trust` experiment's held-out set).
const SIGMA: f32 = 0.01;

/// Runs the experiment (see the module docs).
pub fn heldout(ctx: &Context) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let mut rec = Recorder::new(ctx, "heldout");
    let models = [
        rec.model("mn10-seen5-ipcrnet")?,
        rec.model(HELDOUT_RECIPES[0].name)?,
        rec.model(HELDOUT_RECIPES[1].name)?,
    ];
    let noisy = PairConfig {
        noise: Some([SIGMA, SIGMA]),
        ..PairConfig::default()
    };
    let recommended = pcrnet_core::Options::default().hypotheses;
    // The held-out file name is the trust experiment's: the same pairs.
    for (set, file, classes) in [
        (
            "ModelNet10 held-out classes",
            "trust-mn10-heldout",
            &UNSEEN[..],
        ),
        ("ModelNet10 seen classes", "heldout-mn10-seen", &SEEN[..]),
    ] {
        let spec = folder(ctx, "ModelNet10", Some(classes), noisy);
        let pairs = pair_set(ctx, file, spec)?;
        let first = rec.raw.len();
        for model in &models {
            for method in [
                Method::new(MethodKind::Pcrnet),
                Method::new(MethodKind::Ipcrnet),
                device(recommended),
            ] {
                rec.score(set, method, model.int8(), &pairs, true)?;
            }
        }
        let runs: Vec<&MethodScore> = rec.raw[first..].iter().map(|r| &r.1).collect();
        let chart = success_chart(set, &runs, 90.0);
        rec.plot(if first == 0 { "unseen" } else { "seen" }, &chart)?;
    }
    let table = table(&rec.raw);
    rec.finish(
        "More varied training data and identity pairs, on held-out classes",
        vec![
            format!("ModelNet10 test split, Gaussian noise sigma {SIGMA}, Euler angles U[-45°, 45°], translation U[-1, 1], 512 points. Held-out classes: {}; seen: {}.", UNSEEN.join(", "), SEEN.join(", ")),
            "`mn10-seen5-ipcrnet`: i-PCRNet trained on the five seen classes (the generalisation experiment's). `mn10-seen5-plus-ipcrnet`: the same recipe with the 626 ModelNet40 training airplanes and 1,000 generated shapes (boxes, tori, L shapes) added, for the same 20 x 59 steps; `mn10-seen5-identity-ipcrnet`: the five-class recipe with 5% of its pairs at zero motion (`--identity-share 0.05`). None saw a held-out class.".into(),
            "PCRNet: one pass of the i-PCRNet blob; i-PCRNet: up to 20 passes, the paper's stop rule; device K=10: `pcrnet-core`'s register as in the `trust` experiment (the blob's 8 passes, 10 starting poses, on-device ICP, residual).".into(),
        ],
        vec![table],
        started,
    )
}
