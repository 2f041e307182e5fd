//! Ambiguity: which poses a registration's fit cannot tell apart.
//!
//! A good fit says the source lies on the template; it does not say the
//! pose is the only one that puts it there. A vase turned about its axis,
//! or a table turned half way round, fits as well as the true pose, and the
//! residual alone reports such a pose reliable without a word. This stage
//! looks for the two ways a fit can be blind and reports them in
//! [`Registration::ambiguity`](crate::Registration::ambiguity):
//!
//! ```text
//! refined pose
//!   -> free axis   the point-to-plane normal equations at the pose: a
//!                  rotation that barely moves any source point off the
//!                  template's tangent planes (a continuous symmetry: a
//!                  surface of revolution, a sphere, a plane)
//!   -> turn        the best other start (flip resolution's other finalist,
//!                  or the sweep's best start that ended elsewhere) reached
//!                  a fit about as good (a discrete symmetry: a box, a
//!                  table turned by 180 degrees)
//! ```
//!
//! Both are reported beside the verdict, which they do not change: a pose
//! can be reliable (the source lies on the template) and ambiguous (so
//! would it at another pose). The registration's rotation about a free axis,
//! or its choice between the pose and the turned one, is then arbitrary.
//!
//! Everything is f32 in a fixed order with `libm`, on values the refinement
//! computed in integers, so results are bit-identical on every target.

// Matrix code indexes rows and columns by name, as the algebra does.
#![allow(clippy::needless_range_loop)]

use crate::eigen;
use crate::format::Frame;
use crate::pose::Pose;
use crate::refine::{self, Resolved, Subset};
use crate::template::Template;

/// A rotation of the source about [`FreeAxis`]'s axis with stiffness below
/// this leaves the fit nearly unchanged: the axis is reported free.
///
/// The stiffness is the RMS point-to-plane displacement a rotation of one
/// radian causes, as a share of the paired points' RMS distance from their
/// centroid (1 for a rotation that moves every point straight off its plane;
/// 0 for one that slides them all along it). Measured on generated shapes
/// (the `ambiguity` tests): about its axis a noisy cylinder scores ~0.01, a
/// cone ~0.01, while the least stiff axis of a box, a chair or a
/// one-sided view of a bunny-like blob scores over 0.2.
pub const FREE_AXIS_STIFFNESS: f32 = 0.12;

/// The rival's plane residual may be at most this many times the chosen
/// pose's for the two to count as equally good fits.
pub const TURN_RESIDUAL_RATIO: f32 = 1.3;

/// What a registration's fit cannot tell apart (both `None`: the fit
/// determines the pose).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ambiguity {
    /// A rotation about this axis barely changes the fit: the pose's angle
    /// about it is arbitrary (a continuous symmetry).
    pub axis: Option<FreeAxis>,
    /// Another pose, this turn away, fits about as well: the pose may be
    /// this turn off (a discrete symmetry).
    pub turn: Option<Turn>,
}

impl Ambiguity {
    /// Whether either kind was found.
    pub fn is_ambiguous(&self) -> bool {
        self.axis.is_some() || self.turn.is_some()
    }
}

/// An axis about which a rotation barely changes the fit, in the
/// template's frame (user units).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FreeAxis {
    /// Unit direction (sign arbitrary), template frame.
    pub direction: [f32; 3],
    /// The point of the axis nearest the template frame's model origin
    /// (the template's centroid), template frame, user units.
    pub point: [f32; 3],
    /// How stiff the fit is to a rotation about it (see
    /// [`FREE_AXIS_STIFFNESS`]): below that threshold, 0 is perfectly free.
    pub stiffness: f32,
}

/// A second pose fitting about as well as the chosen one.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Turn {
    /// The rigid motion of the template's frame (user units) taking the
    /// chosen pose to the other: `other = pose.then(&motion)`.
    pub motion: Pose,
    /// Its rotation angle, degrees (0..=180).
    pub degrees: f32,
    /// The other pose's relative plane residual (model units, as
    /// [`Registration::relative_plane_residual`](crate::Registration::relative_plane_residual)).
    pub relative_plane_residual: f32,
}

/// The ambiguity of the refined pose `r` (model frame) of the used points:
/// a free axis from the normal equations at the pose (pairs within
/// `max_distance`), and a turn when `r`'s rival fits within
/// [`TURN_RESIDUAL_RATIO`] of it and within `max_residual`.
pub fn assess(
    frame: &Frame,
    template: &Template<'_>,
    subset: &Subset<'_>,
    r: &Resolved,
    max_distance: f32,
    max_residual: f32,
) -> Ambiguity {
    Ambiguity {
        axis: free_axis(frame, template, subset, &r.pose, max_distance),
        turn: turn(frame, r, max_residual),
    }
}

/// The least stiff rotation axis at `pose` if it is free.
///
/// The normal equations are linearised at the matched template points
/// ([`refine::plane_system`]): about a surface of revolution's axis
/// `q x n` then has no component at all, whatever the source's noise.
/// The rotation block of the point-to-plane normal equations with the
/// translation eliminated (its Schur complement
/// `S = A_rr - A_rt A_tt^-1 A_tr`, so that the answer does not depend on
/// where the origin lies) has the smallest eigenvalue `lambda` along the
/// least stiff axis `u`; `sqrt(lambda / n)` is the RMS plane displacement
/// of a one-radian rotation about it. The translation that goes with it,
/// `t = -A_tt^-1 A_tr u`, places the axis: `t = c x u` for a rotation about
/// the line through `c`, so `c = u x t`.
fn free_axis(
    frame: &Frame,
    template: &Template<'_>,
    subset: &Subset<'_>,
    pose: &Pose,
    max_distance: f32,
) -> Option<FreeAxis> {
    let lim = refine::limit(template, max_distance);
    let (u, t, radius) = least_stiff_twist(template, subset, pose, lim)?;
    let stiffness = displacement_quantile(template, subset, pose, lim, (u, t), radius);
    if stiffness >= FREE_AXIS_STIFFNESS {
        return None;
    }
    let c = cross(u, t);
    Some(FreeAxis {
        direction: u,
        point: frame.to_user(c),
        stiffness,
    })
}

/// The least stiff unit twist `(u, t)` of the normal equations at `pose`
/// (see [`free_axis`]) and the RMS distance of the matched template points
/// from their centroid; `None` with fewer than 6 pairs or no spread.
fn least_stiff_twist(
    template: &Template<'_>,
    subset: &Subset<'_>,
    pose: &Pose,
    lim: u64,
) -> Option<([f32; 3], [f32; 3], f32)> {
    let sys = refine::plane_system(template, subset, pose, lim);
    if sys.pairs < 6 {
        return None;
    }
    let n = sys.pairs as f32;
    let mean = sys.sum.map(|v| v / n);
    let spread = sys.sum_squares / n - (mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]);
    if !(spread.is_finite() && spread > 0.0) {
        return None;
    }
    // Full symmetric A from its upper triangle.
    let mut a = sys.a;
    for i in 0..6 {
        for j in 0..i {
            a[i][j] = a[j][i];
        }
    }
    let att = [
        [a[3][3], a[3][4], a[3][5]],
        [a[4][3], a[4][4], a[4][5]],
        [a[5][3], a[5][4], a[5][5]],
    ];
    // X = A_tt^-1 A_tr, column by column (damped: a plane leaves
    // translations along it free, and those columns are then zero).
    let mut x = [[0f32; 3]; 3];
    for col in 0..3 {
        let rhs = [a[3][col], a[4][col], a[5][col]];
        let solved = eigen::solve_damped(&att, &rhs, 1e-6)?;
        for row in 0..3 {
            x[row][col] = solved[row];
        }
    }
    let mut schur = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            let mut v = a[i][j];
            for k in 0..3 {
                v -= a[i][3 + k] * x[k][j];
            }
            schur[i][j] = v;
        }
    }
    let (_, vectors) = eigen::symmetric(schur);
    let u = vectors[2];
    let t = x.map(|row| -(row[0] * u[0] + row[1] * u[1] + row[2] * u[2]));
    Some((u, t, libm::sqrtf(spread)))
}

/// Resolution of the stiffness: the quantile is read off a histogram of
/// this bin width (shares of the RMS radius per radian).
pub const STIFFNESS_BIN: f32 = 0.005;

/// Bins of that histogram; larger displacements fall into the last.
const BINS: usize = 64;

/// The quantile of the pairs' displacements reported as the stiffness:
/// 4 in 5 pairs move less. Not the RMS, which a few pairs with a poor
/// normal dominate: on a cone sampled with 900 points, 50 points along the
/// sharp rim of its base (where a normal estimated from the nearest points
/// tilts at random) carried 89% of the squares.
const QUANTILE_IN_FIFTHS: u32 = 4;

/// How far a pair moves off its tangent plane under the unit twist
/// `(u, t)` (a rotation of one radian about `u`, with the translation `t`
/// that places the axis), `|(q x n) . u + n . t|`, as a share of `radius`:
/// the [`QUANTILE_IN_FIFTHS`] quantile over the pairs, to the
/// [`STIFFNESS_BIN`] above (so at least one bin), from a histogram
/// ([`BINS`] counters on the stack, no allocation). Infinite without pairs.
fn displacement_quantile(
    template: &Template<'_>,
    subset: &Subset<'_>,
    pose: &Pose,
    lim: u64,
    (u, t): ([f32; 3], [f32; 3]),
    radius: f32,
) -> f32 {
    let step = template.step();
    // u16 counters: a subset holds at most `refine::MAX_SUBSET` (65,535) points.
    let mut bins = [0u16; BINS];
    let mut total = 0u16;
    refine::for_each_pair(template, subset, pose, lim, |pq, index| {
        let (_, n) = template.plane_offset(index, pq);
        let q = template.point(index).map(|v| v as f32 * step);
        let qn = cross(q, n);
        let d =
            qn[0] * u[0] + qn[1] * u[1] + qn[2] * u[2] + n[0] * t[0] + n[1] * t[1] + n[2] * t[2];
        // `as` saturates (and maps NaN to bin 0); the last bin takes the rest.
        let k = (libm::fabsf(d) / radius / STIFFNESS_BIN) as usize;
        let bin = &mut bins[k.min(BINS - 1)];
        *bin = bin.saturating_add(1);
        total = total.saturating_add(1);
    });
    let need = (u64::from(total) * u64::from(QUANTILE_IN_FIFTHS)).div_ceil(5);
    let mut seen = 0u64;
    for (k, &count) in bins.iter().enumerate() {
        seen += u64::from(count);
        if total > 0 && seen >= need {
            return (k + 1) as f32 * STIFFNESS_BIN;
        }
    }
    f32::INFINITY
}

/// The rival of `r` as a [`Turn`], if it fits about as well.
fn turn(frame: &Frame, r: &Resolved, max_residual: f32) -> Option<Turn> {
    let rival = r.rival?;
    let rival_plane = rival.fit.plane_residual;
    let fits = rival_plane <= max_residual
        && rival_plane <= TURN_RESIDUAL_RATIO * r.fit.plane_residual
        && refine::apart(&r.pose, &rival.pose);
    if !fits {
        return None;
    }
    let motion = r.pose.inverse().then(&rival.pose);
    let w = libm::fabsf(motion.rotation[0]).min(1.0);
    Some(Turn {
        motion: frame.pose_to_user(&motion),
        degrees: 2.0 * libm::acosf(w) * (180.0 / core::f32::consts::PI),
        relative_plane_residual: rival_plane,
    })
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
