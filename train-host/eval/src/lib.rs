//! # pcrnet-eval
//!
//! Evaluation of PCRNet models on the host: the registration runners
//! ([`register`]: the device pipeline, the network alone, PointNetLK), the
//! methods compared ([`methods`]: those and the ICP baseline [`icp`]),
//! saved pair sets ([`pairs`]), scoring a method on a set ([`score`], with
//! `pcrnet_train::metrics`), the paper's experiments ([`experiments`],
//! sharing [`report`]) and their plots ([`plot`]).
//!
//! Modules depend one way: `register` below `methods`, `report` below the
//! experiments (`paper`, `trust`, `resampled`, `heldout`, `recipes`), and
//! `experiments` (the dispatch) above them all.

pub mod ambiguity;
pub mod cli;
pub mod experiments;
pub mod heldout;
pub mod icp;
pub mod methods;
pub mod nearest;
pub mod pairs;
pub mod paper;
pub mod plot;
pub mod pointnetlk;
pub mod recipes;
pub mod register;
pub mod report;
pub mod resampled;
pub mod scene;
pub mod symmetry;
pub mod tracking;
pub mod trust;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use pcrnet_core::Pose;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::register::Precision;
use methods::Method;
use pairs::Pair;
use pcrnet_train::metrics;

/// A [`Pose`] from an f64 rotation matrix and translation (quaternion with
/// `w >= 0`, as `pcrnet-core` makes them).
pub fn pose_from_matrix(r: &Matrix3<f64>, t: &Vector3<f64>) -> Pose {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    Pose {
        rotation: [
            (s * q.w) as f32,
            (s * q.i) as f32,
            (s * q.j) as f32,
            (s * q.k) as f32,
        ],
        translation: [t.x as f32, t.y as f32, t.z as f32],
    }
}

/// A model blob with its name.
pub type NamedBlob<'a> = (&'a str, &'a [u8]);

/// The errors of one registration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PairScore {
    /// Rotation error, degrees.
    pub rot_deg: f64,
    /// Translation error.
    pub trans: f64,
    /// Time of the registration, milliseconds.
    pub ms: f64,
    /// Passes, steps or iterations run.
    pub iterations: usize,
    /// The device pipeline's relative (point-to-point) residual (share of the template's size).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual: Option<f64>,
    /// The device pipeline's relative plane residual, what its verdict is
    /// judged on and the confidence scores rank by.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_residual: Option<f64>,
    /// The device pipeline's verdict.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reliable: Option<bool>,
    /// The device pipeline's winning hypothesis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hypothesis: Option<usize>,
    /// The error up to the shape's symmetry: ADD-S ([`symmetry::add_s`])
    /// as a share of the template's diameter ([`symmetry::diameter`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub symmetric_error: Option<f64>,
    /// The device pipeline reported the pose ambiguous (a free axis or a
    /// turn, [`pcrnet_core::ambiguity`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambiguous: Option<bool>,
    /// When the pose was reported ambiguous by a turn and not by a free
    /// axis: the turned rival's plane residual over the pose's (what
    /// [`pcrnet_core::ambiguity::TURN_RESIDUAL_RATIO`] bounds).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_only_ratio: Option<f64>,
    /// The relative feature distance of the device pipeline's pose
    /// ([`pcrnet_core::Int8Model::feature_distance`], int8 blobs), or
    /// PointNetLK's at its final pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub feature_distance: Option<f64>,
    /// The reported ambiguity explains the pose's error
    /// ([`symmetry::explains`]); `None` when none was reported.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub explained: Option<bool>,
    /// The check against the single view from its viewpoint, when the
    /// method ran it ([`methods::Method::view_check`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view: Option<ViewCheck>,
}

/// What [`PairScore::view`] records of a [`pcrnet_core::scene::Verification`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ViewCheck {
    /// Template points the view supports.
    pub supported: u32,
    /// Template points in free space.
    pub violations: u32,
    /// Template points behind the view's surface.
    pub occluded: u32,
    /// The check passed.
    pub passed: bool,
}

impl From<pcrnet_core::scene::Verification> for ViewCheck {
    fn from(v: pcrnet_core::scene::Verification) -> Self {
        ViewCheck {
            supported: v.supported,
            violations: v.violations,
            occluded: v.occluded,
            passed: v.passed,
        }
    }
}

/// A method's scores on a set of pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodScore {
    /// Display name (`i-PCRNet int8 + ICP`).
    pub method: String,
    /// The model blob's name, for network methods.
    pub model: Option<String>,
    /// The summary ([`metrics::Summary`]), times included.
    pub summary: metrics::Summary,
    /// Per-pair scores, in the set's order.
    pub pairs: Vec<PairScore>,
    /// Registrations that failed (scored as the identity pose), with why.
    pub failures: Vec<String>,
    /// How well the device pipeline's residual separates good registrations
    /// (rotation error below 5 degrees) from bad ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<metrics::Confidence>,
}

/// Rotation error (degrees) below which a registration counts as good when
/// judging the confidence (the and the success criterion's 5 degrees).
pub const GOOD_BELOW_DEG: f64 = 5.0;

/// Why a pair could not be registered.
#[derive(Debug, thiserror::Error)]
#[error("pair {index} ({method}): {error}")]
pub struct ScoreError {
    /// Pair index.
    pub index: usize,
    /// Method name.
    pub method: String,
    /// What failed.
    pub error: methods::MethodError,
}

/// Scores `method` (with the named model blob for network methods) on
/// `pairs`. `parallel` spreads pairs over the rayon pool (results are
/// identical; times then include contention, so timing runs use `false`).
///
/// A registration that fails (for example an int8 i-PCRNet estimate that
/// drifts until the moved points leave the input range) is scored as the
/// identity pose, the answer of a method that gives up, and listed in
/// [`MethodScore::failures`]. A missing model is an error.
pub fn score(
    method: &Method,
    model: Option<NamedBlob<'_>>,
    pairs: &[Pair],
    parallel: bool,
) -> Result<MethodScore, ScoreError> {
    let blob = model.map(|(_, b)| b);
    let progress = pcrnet_io::progress::Progress::bar(pairs.len() as u64, method.name(None));
    type Scored = (PairScore, Option<Precision>, Option<String>);
    let one = |(index, p): (usize, &Pair)| -> Result<Scored, ScoreError> {
        progress.inc(1);
        let started = std::time::Instant::now();
        let (pose, iterations, seconds, precision, check, feature_distance, view, failure) =
            match methods::run(method, blob, Some(&p.template), &p.source, p.viewpoint) {
                Ok(o) => (
                    o.pose,
                    o.iterations,
                    o.seconds,
                    o.precision,
                    // The verdict in force: the view's too, when checked.
                    o.check.map(|c| pcrnet_core::Registration {
                        reliable: o.reliable().unwrap_or(c.reliable),
                        ..c
                    }),
                    o.feature_distance,
                    o.view,
                    None,
                ),
                Err(error @ methods::MethodError::NoModel(_)) => {
                    return Err(ScoreError {
                        index,
                        method: method.name(None),
                        error,
                    });
                }
                Err(e) => (
                    Pose::IDENTITY,
                    0,
                    started.elapsed().as_secs_f64(),
                    None,
                    None,
                    None,
                    None,
                    Some(format!("pair {index}: {e}")),
                ),
            };
        Ok((
            PairScore {
                rot_deg: metrics::rotation_error_deg(&pose.rotation_matrix(), &p.r_gt),
                trans: metrics::translation_error(&pose.translation, &p.t_gt),
                ms: seconds * 1e3,
                iterations,
                residual: check.map(|c| c.relative_residual as f64),
                plane_residual: check.map(|c| c.plane_residual as f64),
                reliable: check.map(|c| c.reliable),
                hypothesis: check.map(|c| c.hypothesis),
                symmetric_error: Some(
                    symmetry::add_s(&pose, &symmetry::truth(&p.r_gt, &p.t_gt), &p.template)
                        / symmetry::diameter(&p.template),
                ),
                feature_distance,
                ambiguous: check.map(|c| c.ambiguity.is_ambiguous()),
                turn_only_ratio: check.filter(|c| c.ambiguity.axis.is_none()).and_then(|c| {
                    let t = c.ambiguity.turn?;
                    Some((t.relative_plane_residual / c.relative_plane_residual) as f64)
                }),
                explained: check
                    .filter(|c| c.ambiguity.is_ambiguous())
                    .map(|c| symmetry::explains(&c.ambiguity, &pose, &p.r_gt)),
                view: view.map(ViewCheck::from),
            },
            precision,
            failure,
        ))
    };
    let results: Vec<Scored> = if parallel {
        pairs
            .par_iter()
            .enumerate()
            .map(one)
            .collect::<Result<_, _>>()?
    } else {
        pairs
            .iter()
            .enumerate()
            .map(one)
            .collect::<Result<_, _>>()?
    };
    let precision = results.iter().find_map(|r| r.1);
    let failures: Vec<String> = results.iter().filter_map(|r| r.2.clone()).collect();
    let scores: Vec<PairScore> = results.into_iter().map(|r| r.0).collect();
    let rot: Vec<f64> = scores.iter().map(|s| s.rot_deg).collect();
    let trans: Vec<f64> = scores.iter().map(|s| s.trans).collect();
    let secs: Vec<f64> = scores.iter().map(|s| s.ms / 1e3).collect();
    // Ranked by the plane residual, which the verdict is judged on. A
    // failed registration has none: it counts as unreliable with the worst.
    let confidence = scores.iter().any(|s| s.plane_residual.is_some()).then(|| {
        let residual: Vec<f64> = scores
            .iter()
            .map(|s| s.plane_residual.unwrap_or(f64::INFINITY))
            .collect();
        let reliable: Vec<bool> = scores.iter().map(|s| s.reliable.unwrap_or(false)).collect();
        metrics::Confidence::of(&rot, &residual, &reliable, GOOD_BELOW_DEG)
    });
    Ok(MethodScore {
        method: method.name(precision),
        model: model.map(|(n, _)| n.to_string()),
        summary: metrics::Summary::of(&rot, &trans, Some(&secs)),
        pairs: scores,
        failures,
        confidence,
    })
}
