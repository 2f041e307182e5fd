//! From a sensor frame to the object's pose: the scene stages
//! ([`crate::scene`]) find candidate clusters, the best few are registered
//! to the template, and the best registration wins.
//!
//! **frame -> grid -> plane -> clusters -> points -> registration**, in
//! caller-owned buffers: the label slice of [`crate::scene::labels_len`],
//! a point buffer that bounds each candidate's points, and the model's
//! scratch. Each registration is checked against the frame
//! ([`crate::scene::verify`]) when its intrinsics are known: a candidate is
//! reliable when its pose explains the frame and its residual is within the
//! check's looser bound. The winner is a reliable candidate, the one with
//! the fewest violations of free space (then the lowest relative plane
//! residual); without a reliable one, the same order picks the best,
//! reported not reliable. A frame without a kept cluster has no registration.

use crate::error::Result;
use crate::registration::Registration;
use crate::scene::{self, Organised, SceneOptions, Segmentation, Verification};
use crate::sweep::Sweep;

/// Most candidates registered per frame.
pub const MAX_CANDIDATES: usize = 8;

/// What happened to one registered candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Candidate {
    /// Its place in [`Segmentation::clusters`]' kept list.
    pub cluster: usize,
    /// Points gathered and registered.
    pub points: usize,
    /// Its registration (source = its points, sensor frame).
    pub registration: Registration,
    /// Its pose checked against the frame ([`crate::scene::verify`]), when
    /// the frame's intrinsics are known and the options ask for it.
    pub verification: Option<Verification>,
    /// The verdict. Checked against the frame: the check passed, the
    /// source is not degenerate and the relative plane residual is within
    /// [`crate::scene::VerifySettings::max_residual`]; else the
    /// registration's own verdict.
    pub reliable: bool,
}

/// What [`locate`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// The winning candidate, if any cluster was kept.
    pub best: Option<Candidate>,
    /// Every registered candidate, in the clusters' order (largest first).
    pub tried: heapless::Vec<Candidate, MAX_CANDIDATES>,
    /// The plane, the clusters and why others were dropped.
    pub segmentation: Segmentation,
}

impl Located {
    /// The winner's registration, if any.
    pub fn registration(&self) -> Option<&Registration> {
        self.best.as_ref().map(|c| &c.registration)
    }
}

/// Segments `frame` and registers up to `candidates` (at most
/// [`MAX_CANDIDATES`]) of the largest kept clusters with `register`, each
/// from at most `points.len()` of its points, and checks each registration
/// with `verify` (`None`: not verified). `register` is given the sweep
/// ([`crate::sweep`]) when the scene options name the template's up axis
/// and a plane was found or given, else `None`.
///
/// # Errors
/// What [`scene::segment`] or `register` returns; a candidate whose
/// registration fails with an error is not a reason to give up on the
/// others: only when every tried candidate fails is the first error returned.
pub fn locate<F: Organised>(
    frame: &F,
    scene: &SceneOptions,
    candidates: usize,
    labels: &mut [u16],
    points: &mut [[f32; 3]],
    mut register: impl FnMut(&[[f32; 3]], Option<&Sweep>) -> Result<Registration>,
    mut verify: impl FnMut(&F, &Registration) -> Option<(Verification, f32)>,
) -> Result<Located> {
    let segmentation = scene::segment(frame, scene, labels)?;
    let sweep = match (scene.up, segmentation.plane) {
        (Some(up), Some(plane)) => Some(Sweep {
            plane,
            up,
            yaws: scene.yaws,
        }),
        _ => None,
    };
    let mut tried = heapless::Vec::new();
    let mut first_error = None;
    let kept = &segmentation.clusters.kept;
    for (index, cluster) in kept.iter().enumerate().take(candidates.min(MAX_CANDIDATES)) {
        let n = segmentation.gather(frame, scene, labels, cluster, points);
        let Some(source) = points.get(..n) else {
            continue;
        };
        match register(source, sweep.as_ref()) {
            Ok(registration) => {
                let checked = verify(frame, &registration);
                let reliable = match checked {
                    Some((v, max_residual)) => {
                        v.passed
                            && registration.degenerate.is_none()
                            && registration.relative_plane_residual <= max_residual
                    }
                    None => registration.reliable,
                };
                let _ = tried.push(Candidate {
                    cluster: index,
                    points: n,
                    registration,
                    verification: checked.map(|(v, _)| v),
                    reliable,
                });
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    if tried.is_empty()
        && let Some(e) = first_error
    {
        return Err(e);
    }
    let best = tried
        .iter()
        .copied()
        .reduce(|a, b| if better(&b, &a) { b } else { a });
    Ok(Located {
        best,
        tried,
        segmentation,
    })
}

/// Whether `a` beats `b`: reliable first; then, both checked against the
/// frame, the smaller share of violations; else the lower relative plane
/// residual (the earlier, larger cluster on a tie).
fn better(a: &Candidate, b: &Candidate) -> bool {
    if a.reliable != b.reliable {
        return a.reliable;
    }
    if let (Some(va), Some(vb)) = (a.verification, b.verification) {
        let share =
            |v: Verification| v.violations as f32 / (v.supported + v.violations).max(1) as f32;
        let (sa, sb) = (share(va), share(vb));
        if sa != sb {
            return sa < sb;
        }
    }
    a.registration.relative_plane_residual < b.registration.relative_plane_residual
}
