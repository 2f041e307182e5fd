//! Checking and refining a pose against the template's points: the
//! residual (how well the moved source lies on the template), point-to-point
//! ICP, and flip resolution over several starting poses.
//!
//! Everything runs in the model frame ([`crate::format::Frame`]) on the
//! template's int16 grid ([`Template`]): a source point is moved into the
//! model frame and by the pose in f32 ([`PointMap`]), rounded onto the grid,
//! and matched to its nearest template point by an exact integer search.
//! The sums ICP needs are integers too (exact, order-free); only the 4x4
//! eigenproblem of Horn's method and the final scores are f32, through
//! `libm`. Memory is O(1): nothing depends on the number of points.

use core::num::NonZeroUsize;

mod resolve;
pub(crate) use resolve::apart;
pub use resolve::{
    FLIP_MARGIN, Guide, RIVAL_MIN_TURN_COS, RIVAL_SCREEN_RATIO, Resolved, Rival, SCREEN_CHECK,
    SCREEN_DROP, Unguided, resolve, resolve_starts,
};

use crate::eigen;
use crate::format::Frame;
use crate::pose::{PointMap, Pose};
use crate::template::Template;

/// The source points refinement and scoring use: every `stride`-th point
/// of the cloud (from index 0), moved into the model frame.
#[derive(Debug, Clone, Copy)]
pub struct Subset<'s> {
    /// The cloud, user units.
    pub source: &'s [[f32; 3]],
    /// User units -> model frame.
    pub frame: Frame,
    /// Step between used points (>= 1).
    pub stride: usize,
}

/// Most points a [`Subset`] keeps, whatever `max_points` says: the exact
/// integer sums of ICP and of the degeneracy check stay inside i64 up to
/// this many points of at most 2^15 steps.
pub const MAX_SUBSET: usize = 65_535;

impl<'s> Subset<'s> {
    /// Every point if the cloud has at most `max_points`, else a stride
    /// that keeps at most `max_points` (1..=[`MAX_SUBSET`]) of them.
    pub fn new(source: &'s [[f32; 3]], frame: Frame, max_points: usize) -> Self {
        Subset {
            source,
            frame,
            stride: stride_for(source.len(), max_points),
        }
    }

    fn points(&self) -> impl Iterator<Item = &'s [f32; 3]> + 's {
        self.source.iter().step_by(self.stride.max(1))
    }

    /// The mean of the used points in the model frame (f32 sums in order;
    /// zero for no point).
    pub fn centroid(&self) -> [f32; 3] {
        let (mut sum, mut n) = ([0f32; 3], 0u32);
        for &p in self.points() {
            let q = self.frame.to_model(p);
            for (s, v) in sum.iter_mut().zip(q) {
                *s += v;
            }
            n += 1;
        }
        let n = n.max(1) as f32;
        sum.map(|s| s / n)
    }
}

/// The step between kept points when every k-th point of `len` (from
/// index 0) is kept and at most `most` (clamped to `1..=`[`MAX_SUBSET`])
/// may be: `ceil(len / most)`, at least 1.
pub(crate) fn stride_for(len: usize, most: usize) -> usize {
    let max = NonZeroUsize::new(most.clamp(1, MAX_SUBSET)).unwrap_or(NonZeroUsize::MIN);
    div_ceil(len, max).max(1)
}

/// `a / b` rounded up, with a divisor the compiler sees is not zero (the
/// link-time no-panic proof: `usize::div_ceil` by a clamped value kept a
/// division-by-zero panic at opt-level `s` on the M0 and M3).
fn div_ceil(a: usize, b: NonZeroUsize) -> usize {
    a / b + usize::from(a % b != 0)
}

/// What ICP minimises. (Scoring is the same for both: [`Fit`] carries the
/// point-to-point and the point-to-plane residual.)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Metric {
    /// Distances to the nearest template points (Besl & McKay).
    PointToPoint,
    /// Distances to the tangent planes at the nearest template points,
    /// `n . (p - q)` (Chen & Medioni): a source sampled elsewhere on the
    /// surface than the template's points is not pulled towards them, so
    /// the fit is unbiased, and ICP converges in fewer iterations.
    PointToPlane,
}

/// How well a posed source fits the template (model units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Mean over the used points of `min(d, max_distance)`, `d` the
    /// distance to the nearest template point.
    pub residual: f32,
    /// Share of used points with `d <= max_distance`.
    pub fitness: f32,
    /// Root mean square of `d` over those inliers (0 without inliers).
    pub inlier_rmse: f32,
    /// Mean over the used points of `|n . (p - q)|`, the distance to the
    /// tangent plane at the nearest template point `q`, counting
    /// `max_distance` for a point without one. A right pose scores about
    /// the noise, however the source's samples fall between the
    /// template's; `residual` adds that sampling gap. Measured (the `trust`
    /// experiment), it separates right poses from wrong ones at least as
    /// well as `residual` on every set, and with one threshold for sources
    /// that do and do not share points with the template.
    pub plane_residual: f32,
}

/// `max_distance` (model units) as a squared int16-step limit for the search.
pub(crate) fn limit(template: &Template<'_>, max_distance: f32) -> u64 {
    let steps = max_distance / template.step();
    let sq = steps * steps;
    // Non-finite or huge limits search everything.
    if sq.is_finite() && sq < 1.8e19 {
        sq as u64
    } else {
        u64::MAX - 1
    }
}

/// Scores `pose` (model frame) on the subset: see [`Fit`].
pub fn score(template: &Template<'_>, subset: &Subset<'_>, pose: &Pose, max_distance: f32) -> Fit {
    let map = PointMap::new(subset.frame, pose);
    let lim = limit(template, max_distance);
    let cap = libm::sqrtf(lim as f32);
    let (mut sum, mut sum_sq, mut inliers, mut used) = (0f32, 0f32, 0u32, 0u32);
    let mut plane = 0f32;
    for p in subset.points() {
        let q = template.quantize(map.apply(*p));
        used += 1;
        match template.nearest(q, lim + 1) {
            Some(n) => {
                let d2 = n.distance_squared as f32;
                sum += libm::sqrtf(d2);
                sum_sq += d2;
                inliers += 1;
                plane += libm::fabsf(template.plane_offset(n.index, q).0);
            }
            None => {
                sum += cap;
                plane += cap;
            }
        }
    }
    let step = template.step();
    let n = used.max(1) as f32;
    Fit {
        residual: sum / n * step,
        plane_residual: plane / n * step,
        fitness: inliers as f32 / n,
        inlier_rmse: if inliers > 0 {
            libm::sqrtf(sum_sq / inliers as f32) * step
        } else {
            0.0
        },
    }
}

/// ICP settings (model units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpSettings {
    /// What each iteration minimises.
    pub metric: Metric,
    /// Most iterations.
    pub iterations: usize,
    /// Stop once an update's `||dT - I||_F` is below this.
    pub tolerance: f32,
    /// Pairs farther apart than this are left out of the fit.
    pub max_distance: f32,
}

/// Point-to-point ICP from `start` (model frame): each iteration pairs
/// every used source point with its nearest template point within
/// `max_distance` and applies the rigid motion that best aligns the pairs
/// (Horn, *Closed-form solution of absolute orientation using unit
/// quaternions*, JOSA A 1987). Returns the pose and the iterations run;
/// stops early on the tolerance or when fewer than 3 pairs remain.
pub fn icp(
    template: &Template<'_>,
    subset: &Subset<'_>,
    start: Pose,
    settings: &IcpSettings,
) -> (Pose, usize) {
    let run = icp_run(template, subset, start, settings);
    (run.pose, run.iterations)
}

/// Where an ICP run ended ([`icp_run`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct IcpRun {
    /// The refined pose (model frame).
    pub pose: Pose,
    /// Iterations that updated the pose.
    pub iterations: usize,
    /// Whether it stopped on its own (converged, or too few pairs) rather
    /// than at the iteration budget: a run that did not can be resumed from
    /// `pose` with the same result as one longer run.
    pub stopped: bool,
}

/// [`icp`], saying whether the run stopped on its own.
pub(crate) fn icp_run(
    template: &Template<'_>,
    subset: &Subset<'_>,
    start: Pose,
    settings: &IcpSettings,
) -> IcpRun {
    let lim = limit(template, settings.max_distance);
    let mut pose = start;
    for done in 1..=settings.iterations {
        let step = match settings.metric {
            Metric::PointToPoint => icp_step(template, subset, &pose, lim),
            Metric::PointToPlane => plane_step(template, subset, &pose, lim),
        };
        let Some(delta) = step else {
            return IcpRun {
                pose,
                iterations: done - 1,
                stopped: true,
            };
        };
        pose = pose.then(&delta);
        if delta.distance_to_identity_squared() < settings.tolerance * settings.tolerance {
            return IcpRun {
                pose,
                iterations: done,
                stopped: true,
            };
        }
    }
    IcpRun {
        pose,
        iterations: settings.iterations,
        stopped: false,
    }
}

/// One ICP update (model frame), or `None` with fewer than 3 pairs.
fn icp_step(template: &Template<'_>, subset: &Subset<'_>, pose: &Pose, lim: u64) -> Option<Pose> {
    let map = PointMap::new(subset.frame, pose);
    let (mut n, mut sp, mut sq) = (0i64, [0i64; 3], [0i64; 3]);
    let mut spq = [[0i64; 3]; 3];
    for p in subset.points() {
        let p = template.quantize(map.apply(*p));
        let Some(nb) = template.nearest(p, lim + 1) else {
            continue;
        };
        let q = template.point(nb.index);
        n += 1;
        for i in 0..3 {
            sp[i] += p[i] as i64;
            sq[i] += q[i] as i64;
            for j in 0..3 {
                spq[i][j] += p[i] as i64 * q[j] as i64;
            }
        }
    }
    if n < 3 {
        return None;
    }
    // n^2 x the centred cross-covariance, exact: |n spq| and |sp sq| stay
    // below 2^62 for n <= 65535 points of at most 2^15 steps.
    let mut h = [[0f32; 3]; 3];
    let mut scale = 0f32;
    for i in 0..3 {
        for j in 0..3 {
            h[i][j] = (n * spq[i][j] - sp[i] * sq[j]) as f32;
            scale = scale.max(libm::fabsf(h[i][j]));
        }
    }
    let rotation = if scale > 0.0 {
        for row in h.iter_mut() {
            for v in row.iter_mut() {
                *v /= scale;
            }
        }
        horn_rotation(&h)
    } else {
        Pose::IDENTITY.rotation
    };
    let r = Pose {
        rotation,
        translation: [0.0; 3],
    };
    let nf = n as f32;
    let mean_p = sp.map(|v| v as f32 / nf);
    let mean_q = sq.map(|v| v as f32 / nf);
    let [px, py, pz] = r.transform_point(mean_p);
    let ([qx, qy, qz], step) = (mean_q, template.step());
    Some(Pose {
        rotation,
        translation: [(qx - px) * step, (qy - py) * step, (qz - pz) * step],
    })
}

/// The point-to-plane normal equations at a pose (model units): for each
/// used source point `p` (moved by the pose, on the grid) with a nearest
/// template point `q` within the search limit, the row
/// `j = [x x n, n]` of the linearised motion `(omega, t)` and the offset
/// `r = n . (q - p)`, summed in point order as `a = sum j j^T` (upper
/// triangle) and `b = sum j r`. [`icp_system`] and [`plane_system`] say
/// which `x` and `n`.
pub(crate) struct PlaneSystem {
    /// `sum j j^T`, upper triangle (rows: omega x y z, then t x y z).
    pub a: [[f32; 6]; 6],
    /// `sum j r`.
    pub b: [f32; 6],
    /// Pairs summed.
    pub pairs: u32,
    /// The sum of the points `x` the rotation was linearised at (model
    /// units, in point order); zero in [`icp_system`]'s.
    pub sum: [f32; 3],
    /// The sum of their squared norms; zero in [`icp_system`]'s.
    pub sum_squares: f32,
}

impl PlaneSystem {
    const EMPTY: PlaneSystem = PlaneSystem {
        a: [[0f32; 6]; 6],
        b: [0f32; 6],
        pairs: 0,
        sum: [0f32; 3],
        sum_squares: 0.0,
    };

    /// Adds the pair of `x` (the rotation's linearisation point), normal
    /// `n` and offset `r` (model units); with `MOMENTS` also `x` and its
    /// squared norm to the moments (an ICP step has no use for them, and
    /// without them its sums fit the FPU's registers better).
    #[inline(always)]
    fn add<const MOMENTS: bool>(&mut self, x: [f32; 3], n: [f32; 3], r: f32) {
        let j = [
            x[1] * n[2] - x[2] * n[1],
            x[2] * n[0] - x[0] * n[2],
            x[0] * n[1] - x[1] * n[0],
            n[0],
            n[1],
            n[2],
        ];
        for i in 0..6 {
            for k in i..6 {
                self.a[i][k] += j[i] * j[k];
            }
            self.b[i] += j[i] * r;
        }
        if MOMENTS {
            for (s, v) in self.sum.iter_mut().zip(x) {
                *s += v;
            }
            self.sum_squares += x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
        }
        self.pairs += 1;
    }
}

/// Calls `f(p, i)` for every used source point `p` (moved by `pose`, on
/// the grid) whose nearest template point `i` lies within the squared step
/// limit `lim`, in point order.
pub(crate) fn for_each_pair(
    template: &Template<'_>,
    subset: &Subset<'_>,
    pose: &Pose,
    lim: u64,
    mut f: impl FnMut([i16; 3], usize),
) {
    let map = PointMap::new(subset.frame, pose);
    for p in subset.points() {
        let pq = template.quantize(map.apply(*p));
        if let Some(nb) = template.nearest(pq, lim + 1) {
            f(pq, nb.index);
        }
    }
}

/// The [`PlaneSystem`] of an ICP step at `pose`, pairing points within the
/// squared step limit `lim`: each rotation linearised at the moved source
/// point `p`, with the template's stored normal over 127
/// ([`Template::stored_plane_offset`]) rather than the unit normal. Its
/// length lies in 0.948..1.051 (checked at load), so each pair's equation
/// is weighted by `(|n| / 127)^2`, between 0.90 and 1.10: the price of no
/// square root and four divisions per pair (1.6 M instructions of a
/// default registration on the Cortex-M4F, 25.7 M -> 23.8 M; the `trust`
/// experiment at 1,000 pairs a set gave the same poses within noise:
/// more than 5 degrees off 1 / 16 / 11 / 22 against 1 / 15 / 12 / 22, the
/// same medians to 0.003 degrees). No moments.
pub(crate) fn icp_system(
    template: &Template<'_>,
    subset: &Subset<'_>,
    pose: &Pose,
    lim: u64,
) -> PlaneSystem {
    const STORED: f32 = 1.0 / 127.0;
    let step = template.step();
    let mut sys = PlaneSystem::EMPTY;
    for_each_pair(template, subset, pose, lim, |pq, index| {
        let (offset, n) = template.stored_plane_offset(index, pq);
        let x = pq.map(|v| v as f32 * step);
        sys.add::<false>(x, n.map(|v| v * STORED), offset * STORED * step);
    });
    sys
}

/// The exact [`PlaneSystem`] at `pose` with unit normals, each rotation
/// linearised at the nearest template point `q` (not the source point), and
/// its moments: what the ambiguity check reads. At a converged pose `p`
/// lies near `q`'s tangent plane, and `q x n` carries neither the source's
/// noise nor the gap between the two samplings of the surface, so a
/// rotation the template's shape cannot observe shows as a zero.
pub(crate) fn plane_system(
    template: &Template<'_>,
    subset: &Subset<'_>,
    pose: &Pose,
    lim: u64,
) -> PlaneSystem {
    let step = template.step();
    let mut sys = PlaneSystem::EMPTY;
    for_each_pair(template, subset, pose, lim, |pq, index| {
        let (offset, n) = template.plane_offset(index, pq);
        let q = template.point(index).map(|v| v as f32 * step);
        sys.add::<true>(q, n, offset * step);
    });
    sys
}

/// One point-to-plane ICP update (model frame): the small motion
/// `(omega, t)` minimising `sum (n . (R p + t - q))^2` linearised at the
/// current pose (`R ~ I + [omega]x`; Low, *Linear least-squares
/// optimization for point-to-plane ICP*, 2004), solved as 6x6 normal
/// equations ([`icp_system`], accumulated in f32 in point order) and
/// applied as the exact rotation of angle `|omega|`. `None` with fewer
/// than 6 pairs or a singular system.
fn plane_step(template: &Template<'_>, subset: &Subset<'_>, pose: &Pose, lim: u64) -> Option<Pose> {
    let sys = icp_system(template, subset, pose, lim);
    if sys.pairs < 6 {
        return None;
    }
    let x = eigen::solve_damped(&sys.a, &sys.b, 1e-6)?;
    let omega = [x[0], x[1], x[2]];
    let angle = libm::sqrtf(omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]);
    let rotation = if angle > 0.0 {
        let s = libm::sinf(0.5 * angle) / angle;
        [
            libm::cosf(0.5 * angle),
            omega[0] * s,
            omega[1] * s,
            omega[2] * s,
        ]
    } else {
        Pose::IDENTITY.rotation
    };
    Some(Pose {
        rotation,
        translation: [x[3], x[4], x[5]],
    })
}

/// The unit quaternion (`w >= 0`) of the rotation taking the source onto the
/// template for the cross-covariance `s[i][j] = sum p_i q_j`: the eigenvector
/// of Horn's symmetric 4x4 matrix with the largest eigenvalue.
fn horn_rotation(s: &[[f32; 3]; 3]) -> [f32; 4] {
    let [[xx, xy, xz], [yx, yy, yz], [zx, zy, zz]] = *s;
    let n = [
        [xx + yy + zz, yz - zy, zx - xz, xy - yx],
        [0.0, xx - yy - zz, xy + yx, zx + xz],
        [0.0, 0.0, -xx + yy - zz, yz + zy],
        [0.0, 0.0, 0.0, -xx - yy + zz],
    ];
    let (_, vectors) = eigen::symmetric(n);
    let q = vectors[0];
    let norm = libm::sqrtf(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if !(norm.is_finite() && norm > 0.0) {
        return Pose::IDENTITY.rotation;
    }
    let s = if q[0] < 0.0 { -1.0 / norm } else { 1.0 / norm };
    q.map(|v| v * s)
}

/// What the shape of a source says about how well a pose can be determined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Degeneracy {
    /// All used points (nearly) coincide: no rotation can be recovered.
    Point,
    /// The points (nearly) lie on a line: the rotation about it is free.
    Line,
}

/// Classifies the spread of the used points (model frame): `Point` when
/// the largest standard deviation along a principal axis is below
/// `min_extent`, `Line` when the second is below 1% of the largest.
///
/// The points are moved by minus their mean (f32, summed in order) before
/// they are rounded onto the template's int16 grid: the grid spans about
/// 32767 steps either side of the template, and a source far from the
/// template's frame would otherwise clamp to its edge and look like one point.
pub fn degeneracy(
    template: &Template<'_>,
    subset: &Subset<'_>,
    min_extent: f32,
) -> Option<Degeneracy> {
    let (mut sum, mut count) = ([0f32; 3], 0u32);
    for p in subset.points() {
        let q = subset.frame.to_model(*p);
        for k in 0..3 {
            sum[k] += q[k];
        }
        count += 1;
    }
    let n = count.max(1) as f32;
    let centre = Pose {
        rotation: Pose::IDENTITY.rotation,
        translation: sum.map(|v| -v / n),
    };
    let map = PointMap::new(subset.frame, &centre);
    let (mut n, mut s, mut ss) = (0i64, [0i64; 3], [[0i64; 3]; 3]);
    for p in subset.points() {
        let p = template.quantize(map.apply(*p));
        n += 1;
        for i in 0..3 {
            s[i] += p[i] as i64;
            for j in 0..3 {
                ss[i][j] += p[i] as i64 * p[j] as i64;
            }
        }
    }
    if n == 0 {
        return Some(Degeneracy::Point);
    }
    // n^2 x the covariance, in squared steps.
    let mut c = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (n * ss[i][j] - s[i] * s[j]) as f32;
        }
    }
    let (values, _) = eigen::symmetric(c);
    let nf = n as f32;
    let sd = values.map(|v| libm::sqrtf(v.max(0.0)) / nf * template.step());
    if sd[0] < min_extent {
        Some(Degeneracy::Point)
    } else if sd[1] < 0.01 * sd[0] {
        Some(Degeneracy::Line)
    } else {
        None
    }
}
