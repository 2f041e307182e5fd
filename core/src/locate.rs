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
use crate::scene::{self, Organised, Plane, SceneOptions, Segmentation, Verification};
use crate::sweep::Sweep;

/// Most candidates registered per frame.
pub const MAX_CANDIDATES: usize = 8;

/// Where the sensor stands in a frame's coordinates: its origin (a depth
/// image's points are in the camera's frame; an organised cloud's are
/// taken to be). Each candidate is one side of an object seen from there,
/// so the yaw sweep's starts are placed along the plane by what the sensor
/// would see of the template ([`crate::scene::visible`]).
///
/// Measured on the `scene` experiment (50 frames per camera, seeds 1 and
/// 2, ToF / RGB-D, session 51), unplaced -> placed: the sweep's success
/// (5 degrees, 0.05) 62 / 54% -> 68 / 68% and 58 / 66% -> 58 / 68%,
/// reliable but more than 5 degrees off 22 / 26% -> 20 / 18% and 24 / 22%
/// -> 26 / 24%; frames without the object reported reliable the same but
/// one. The network's hypotheses (no `up`) found more right poses too
/// (34 / 20% -> 36 / 24%, 16 / 18% -> 26 / 20%) but more wrong ones
/// reliable (8 / 18% -> 14 / 20%, 18 / 14% -> 28 / 20%), so they start
/// where the network puts them.
pub const SENSOR: [f32; 3] = [0.0; 3];

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
    /// the candidate's bound (the larger of
    /// [`crate::scene::VerifySettings::max_residual`] and the options'
    /// `max_residual`); else the registration's own verdict.
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

/// Where [`locate`] asks a candidate's registration to start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start<'a> {
    /// The network's hypotheses ([`crate::Int8Model::register`]).
    Network,
    /// The yaw sweep on the plane ([`crate::sweep`]).
    Sweep(&'a Sweep),
    /// This pose (user units), refined by ICP alone: the other pose of a
    /// reported turn.
    Pose(&'a crate::pose::Pose),
}

/// Where the object was (a tracked object's last pose, [`crate::follow`]):
/// every candidate is registered from `pose` ([`Start::Pose`]) and the
/// clusters are tried nearest `centre` first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior<'a> {
    /// The last pose (sensor frame onto template, user units).
    pub pose: &'a crate::pose::Pose,
    /// Where it put the template's centre (sensor frame).
    pub centre: [f32; 3],
}

/// Segments `frame` and registers up to `candidates` (at most
/// [`MAX_CANDIDATES`]) of the largest kept clusters with `register` (with
/// a `prior`, the nearest its centre, each from its pose), each
/// from at most `points.len()` of its points, and checks each registration
/// with `check` (given the plane the segmentation took out, if any, for
/// [`crate::scene::verify::verify`]'s test beneath the surface; `None`: not
/// verified). `register` starts from the sweep
/// ([`crate::sweep`]) when the scene options name the template's up axis
/// and a plane was found or given, else from the network's hypotheses.
///
/// A checked registration that reports a turn (a second pose fitting the
/// template about as well, [`crate::ambiguity`]) is registered again from
/// the turned pose and checked too: the frame sees what the template's fit
/// cannot (which side faces the sensor, what stands in front), and the pose
/// with the smaller share of violations is kept, its turn pointing to the
/// other (the margin: [`TURN_MARGIN`]).
///
/// # Errors
/// What [`scene::segment`] or `register` returns; a candidate whose
/// registration fails with an error is not a reason to give up on the
/// others: only when every tried candidate fails is the first error returned.
#[allow(clippy::too_many_arguments)]
pub fn locate<F: Organised>(
    frame: &F,
    scene: &SceneOptions,
    candidates: usize,
    prior: Option<Prior<'_>>,
    labels: &mut [u16],
    points: &mut [[f32; 3]],
    mut register: impl FnMut(&[[f32; 3]], Start<'_>) -> Result<Registration>,
    mut check: impl FnMut(&F, &Registration, Option<Plane>) -> Option<(Verification, f32)>,
) -> Result<Located> {
    let segmentation = scene::segment(frame, scene, labels)?;
    let surface = segmentation.plane;
    let mut verify = |f: &F, r: &Registration| check(f, r, surface);
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
    let mut used = 0u32;
    for _ in 0..candidates.min(MAX_CANDIDATES) {
        let Some((index, cluster)) =
            next_cluster(kept, prior.map(|p| p.centre), used).and_then(|i| Some((i, kept.get(i)?)))
        else {
            break;
        };
        used |= 1 << index;
        let n = segmentation.gather(frame, scene, labels, cluster, points);
        let Some(source) = points.get(..n) else {
            continue;
        };
        let start = match (prior, &sweep) {
            (Some(prior), _) => Start::Pose(prior.pose),
            (None, Some(sweep)) => Start::Sweep(sweep),
            (None, None) => Start::Network,
        };
        match register(source, start) {
            Ok(registration) => {
                let checked = verify(frame, &registration);
                let (registration, checked) = settle_turn(
                    frame,
                    source,
                    registration,
                    checked,
                    &mut register,
                    &mut verify,
                );
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

// Every kept cluster has a bit in `next_cluster`'s `used`.
const _: () = assert!(scene::cluster::MAX_CLUSTERS <= u32::BITS as usize);

/// The next kept cluster to try among those not in `used` (bit `i` for
/// cluster `i`): the first (the largest) without `centre`, else the one
/// whose centroid is nearest it (the first on a tie).
fn next_cluster(kept: &[scene::Cluster], centre: Option<[f32; 3]>, used: u32) -> Option<usize> {
    let distance = |k: &scene::Cluster| {
        centre.map_or(0.0, |c| {
            let d = [
                k.centroid[0] - c[0],
                k.centroid[1] - c[1],
                k.centroid[2] - c[2],
            ];
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        })
    };
    kept.iter()
        .enumerate()
        .filter(|&(i, _)| i < u32::BITS as usize && used & (1 << i) == 0)
        .fold(None, |best: Option<(usize, f32)>, (i, k)| {
            let d = distance(k);
            match best {
                Some((_, b)) if b <= d => best,
                _ => Some((i, d)),
            }
        })
        .map(|(i, _)| i)
}

/// `registration` and its check, or the other pose of its reported turn
/// when the frame explains that one better: registered from the turned pose
/// (ICP alone), checked, and kept when its share of violations is smaller
/// by [`TURN_MARGIN`] and it does not fail a check `registration` passes;
/// its turn then points back to `registration`'s pose. Unchanged
/// without a turn, without a check, or when the other pose fails.
fn settle_turn<F: Organised>(
    frame: &F,
    source: &[[f32; 3]],
    registration: Registration,
    checked: Option<(Verification, f32)>,
    register: &mut impl FnMut(&[[f32; 3]], Start<'_>) -> Result<Registration>,
    verify: &mut impl FnMut(&F, &Registration) -> Option<(Verification, f32)>,
) -> (Registration, Option<(Verification, f32)>) {
    let (Some(turn), Some((v, _))) = (registration.ambiguity.turn, checked) else {
        return (registration, checked);
    };
    let turned = registration.pose.then(&turn.motion);
    let Ok(mut other) = register(source, Start::Pose(&turned)) else {
        return (registration, checked);
    };
    let Some(other_checked) = verify(frame, &other) else {
        return (registration, checked);
    };
    // A pose the check passes is not given up for one it fails (the share
    // of violations does not count the points outside the frame).
    let worse = v.passed && !other_checked.0.passed;
    if worse || violation_share(other_checked.0) + TURN_MARGIN > violation_share(v) {
        return (registration, checked);
    }
    other.ambiguity.turn = Some(crate::ambiguity::Turn {
        motion: other.pose.inverse().then(&registration.pose),
        degrees: turn.degrees,
        relative_plane_residual: registration.relative_plane_residual,
    });
    (other, Some(other_checked))
}

/// The relative plane residual a candidate of `frame` is judged at when it
/// is checked against the frame (the scene options' `verify` and a frame
/// with intrinsics): the larger of the check's and `options`' bound. `None`
/// when candidates are not checked (their registrations' own verdicts
/// stand). `Int8Model::locate` runs each registration with it, so that
/// its turn is judged at the same bound.
pub fn checked_bound<F: Organised>(
    frame: &F,
    scene: &SceneOptions,
    options: &crate::Options,
) -> Option<f32> {
    let settings = scene.verify.filter(|_| frame.intrinsics().is_some())?;
    Some(settings.max_residual.max(options.max_residual))
}

/// The other pose of a turn replaces a registration's only when its share
/// of violations is smaller by at least this much.
///
/// Measured on the `scene` experiment (seeds 1 and 2, 50 frames per
/// camera, ToF / RGB-D): against not settling turns, success within 5
/// degrees rose from 62 / 60% to 62 / 64% (seed 2: 54 / 72%, unchanged)
/// with the sweep and from 18 / 10% to 26 / 18% (seed 2: 6 / 8% to 14 /
/// 16%) with the network's hypotheses; frames without the object reported
/// reliable rose by one in four of the eight cells. Without a margin
/// (any smaller share) seed 2's ToF sweep lost a frame.
pub const TURN_MARGIN: f32 = 0.05;

/// Template points in front of what the sensor saw, as a share of those it
/// saw something at: supported or violating.
fn violation_share(v: Verification) -> f32 {
    v.violations as f32 / (v.supported + v.violations).max(1) as f32
}

/// Whether `a` beats `b`: reliable first; then, both checked against the
/// frame, the smaller share of violations; else the lower relative plane
/// residual (the earlier, larger cluster on a tie).
fn better(a: &Candidate, b: &Candidate) -> bool {
    if a.reliable != b.reliable {
        return a.reliable;
    }
    if let (Some(va), Some(vb)) = (a.verification, b.verification) {
        let (sa, sb) = (violation_share(va), violation_share(vb));
        if sa != sb {
            return sa < sb;
        }
    }
    a.registration.relative_plane_residual < b.registration.relative_plane_residual
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ambiguity::{Ambiguity, Turn};
    use crate::pose::Pose;
    use crate::scene::OrganisedPoints;

    fn registration(pose: Pose, turn: Option<Turn>) -> Registration {
        Registration {
            pose,
            residual: 0.01,
            relative_residual: 0.01,
            fitness: 1.0,
            inlier_rmse: 0.01,
            plane_residual: 0.005,
            relative_plane_residual: 0.005,
            hypothesis: 0,
            passes: 0,
            lk_iterations: 0,
            icp_iterations: 3,
            saturated: 0,
            out_of_range: 0,
            degenerate: None,
            ambiguity: Ambiguity { axis: None, turn },
            reliable: true,
        }
    }

    fn check(violations: u32) -> (Verification, f32) {
        let v = Verification {
            supported: 100,
            violations,
            occluded: 0,
            unobserved: 0,
            outside: 0,
            passed: violations < 10,
        };
        (v, 0.025)
    }

    /// With a prior the clusters are tried nearest its centre first, not
    /// largest first (the box about a followed object may hold a larger
    /// neighbour); without one, as kept.
    #[test]
    fn clusters_are_tried_nearest_the_prior_first() {
        let cluster = |cells: u32, x: f32| scene::Cluster {
            label: 0,
            cells,
            min: [x; 3],
            max: [x; 3],
            centroid: [x, 0.0, 2.0],
            radius: 0.1,
            span: [0; 4],
        };
        let kept = [cluster(300, 1.0), cluster(200, 0.1), cluster(100, -0.5)];
        let order = |centre| {
            let mut used = 0u32;
            core::iter::from_fn(|| {
                let i = next_cluster(&kept, centre, used)?;
                used |= 1 << i;
                Some(i)
            })
            .collect::<heapless::Vec<usize, 4>>()
        };
        assert_eq!(order(None).as_slice(), &[0, 1, 2]);
        assert_eq!(order(Some([0.0, 0.0, 2.0])).as_slice(), &[1, 2, 0]);
        assert_eq!(order(Some([2.0, 0.0, 2.0])).as_slice(), &[0, 1, 2]);
    }

    #[test]
    fn the_frame_settles_a_turn_only_by_a_clear_margin() {
        let points = [[0f32; 3]];
        let frame = OrganisedPoints::new(&points, 1).unwrap();
        let half = Pose {
            rotation: [0.0, 0.0, 0.0, 1.0],
            translation: [0.0; 3],
        };
        let turn = Turn {
            motion: half,
            degrees: 180.0,
            relative_plane_residual: 0.006,
        };
        let first = registration(Pose::IDENTITY, Some(turn));
        // The first pose leaves 20 of 120 seen points in free space (17%).
        for (other_violations, switched) in [(2, true), (18, false), (40, false)] {
            let mut register = |_: &[[f32; 3]], start: Start<'_>| match start {
                Start::Pose(p) => Ok(registration(*p, None)),
                _ => Err(crate::Error::EmptyCloud),
            };
            let mut verify = |_: &OrganisedPoints<'_>, r: &Registration| {
                Some(check(if r.pose == Pose::IDENTITY {
                    20
                } else {
                    other_violations
                }))
            };
            let (kept, checked) = settle_turn(
                &frame,
                &points,
                first,
                Some(check(20)),
                &mut register,
                &mut verify,
            );
            if switched {
                assert_eq!(kept.pose.rotation, half.rotation);
                assert_eq!(checked.unwrap().0.violations, other_violations);
                // Its turn leads back to the first pose.
                let back = kept.pose.then(&kept.ambiguity.turn.unwrap().motion);
                assert!(libm::fabsf(back.rotation[0]) > 0.9999, "{back:?}");
            } else {
                assert_eq!(kept, first);
                assert_eq!(checked.unwrap().0.violations, 20);
            }
        }
        // A pose the check passes (9 of 109 in free space) stays against one
        // with none in free space that fails it (its points off the frame).
        let mut register = |_: &[[f32; 3]], start: Start<'_>| match start {
            Start::Pose(p) => Ok(registration(*p, None)),
            _ => Err(crate::Error::EmptyCloud),
        };
        let mut verify = |_: &OrganisedPoints<'_>, r: &Registration| {
            Some(if r.pose == Pose::IDENTITY {
                check(9)
            } else {
                let (v, bound) = check(0);
                (
                    Verification {
                        outside: 300,
                        passed: false,
                        ..v
                    },
                    bound,
                )
            })
        };
        let (kept, _) = settle_turn(
            &frame,
            &points,
            first,
            Some(check(9)),
            &mut register,
            &mut verify,
        );
        assert_eq!(kept, first);
        // No turn, or no check: nothing to settle.
        let plain = registration(Pose::IDENTITY, None);
        let mut register = |_: &[[f32; 3]], _: Start<'_>| Ok(registration(half, None));
        let mut verify = |_: &OrganisedPoints<'_>, _: &Registration| Some(check(0));
        let (kept, _) = settle_turn(
            &frame,
            &points,
            plain,
            Some(check(20)),
            &mut register,
            &mut verify,
        );
        assert_eq!(kept, plain);
        let (kept, checked) = settle_turn(&frame, &points, first, None, &mut register, &mut verify);
        assert_eq!((kept, checked), (first, None));
    }
}
