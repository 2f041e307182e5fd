//! The dominant plane of a frame (the table or floor an object stands on):
//! seeded RANSAC over the sampling grid, then a least-squares refit.
//!
//! RANSAC (Fischler & Bolles, 1981): each of `iterations` trials draws
//! three grid cells with [`SplitMix64`], makes the plane through their
//! points and counts the cells within `distance` of it; the trial with the
//! most inliers wins (the first on a tie). The winner is refitted to its
//! inliers (the normal is the covariance's smallest eigenvector,
//! [`crate::eigen::symmetric`]; PCL's `SACSegmentation` with
//! `optimize_coefficients` does the same) and its inliers counted again.
//! Every sum runs in grid order in f32, so the plane is the same bits on
//! every target.

use super::depth::Organised;
use super::grid::Grid;
use crate::eigen;
use crate::random::SplitMix64;

/// A plane `normal . p + offset = 0` in the sensor frame, `normal` of unit
/// length and turned towards the sensor (`offset > 0`: the sensor, at the
/// origin, is on the side the normal points to).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Plane {
    /// Unit normal, towards the sensor.
    pub normal: [f32; 3],
    /// Offset: the sensor's distance from the plane, user units.
    pub offset: f32,
}

impl Plane {
    /// The plane through `a`, `b`, `c`, or `None` when they are (nearly)
    /// on one line or the plane passes through the sensor.
    pub fn through(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Option<Plane> {
        let e = sub(b, a);
        let f = sub(c, a);
        let n = cross(e, f);
        let scale = dot(e, e) * dot(f, f);
        // |e x f|^2 = |e|^2 |f|^2 sin^2: below 1e-4 the corner is under ~0.6 deg.
        let area2 = dot(n, n);
        if area2.is_nan() || area2 <= 1e-4 * scale {
            return None;
        }
        Plane::from_normal(n, a)
    }

    /// The plane with normal `n` (any length) through `p`, turned towards
    /// the sensor; `None` for a zero normal or a plane through the sensor.
    pub fn from_normal(n: [f32; 3], p: [f32; 3]) -> Option<Plane> {
        let length = libm::sqrtf(dot(n, n));
        if !length.is_finite() || length <= 0.0 {
            return None;
        }
        let mut normal = [n[0] / length, n[1] / length, n[2] / length];
        let mut offset = -dot(normal, p);
        if !offset.is_finite() || offset == 0.0 {
            return None;
        }
        if offset < 0.0 {
            normal = [-normal[0], -normal[1], -normal[2]];
            offset = -offset;
        }
        Some(Plane { normal, offset })
    }

    /// Signed distance of `p`: positive on the sensor's side.
    pub fn distance(&self, p: [f32; 3]) -> f32 {
        dot(self.normal, p) + self.offset
    }
}

/// What [`find`] tries.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlaneSearch {
    /// RANSAC trials.
    pub iterations: u32,
    /// A cell is on the plane within this distance (user units).
    pub distance: f32,
    /// The plane must hold at least this share of the valid cells.
    pub min_share: f32,
    /// Seed of the cell draws.
    pub seed: u64,
}

/// The plane found, with its support.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FoundPlane {
    /// The refitted plane.
    pub plane: Plane,
    /// Grid cells within `distance` of it.
    pub inliers: u32,
    /// Valid grid cells in all.
    pub valid: u32,
}

/// Draws per cell of a trial before the trial is given up (a cell may hold
/// no point).
const DRAWS_PER_CELL: usize = 8;

/// The dominant plane of `frame` on `grid`, or `None` when no trial finds
/// a plane holding `min_share` of the valid cells (fewer than three valid
/// cells, one line of points, clutter without a surface).
pub fn find<F: Organised>(frame: &F, grid: &Grid, search: &PlaneSearch) -> Option<FoundPlane> {
    let cells = grid.cells();
    let valid = grid.count(frame, |_| true);
    if valid < 3 || cells == 0 {
        return None;
    }
    let mut random = SplitMix64(search.seed);
    let (columns, rows) = (grid.columns(), grid.rows());
    let draw = |random: &mut SplitMix64| {
        (0..DRAWS_PER_CELL).find_map(|_| {
            let gx = random.below(columns);
            grid.point(frame, gx, random.below(rows))
        })
    };
    let mut best: Option<(Plane, u32)> = None;
    for _ in 0..search.iterations {
        let (Some(a), Some(b), Some(c)) = (draw(&mut random), draw(&mut random), draw(&mut random))
        else {
            continue;
        };
        let Some(plane) = Plane::through(a, b, c) else {
            continue;
        };
        let inliers = grid.count(frame, |p| libm::fabsf(plane.distance(p)) <= search.distance);
        if best.is_none_or(|(_, most)| inliers > most) {
            best = Some((plane, inliers));
        }
    }
    let (plane, _) = best?;
    let plane = refit(frame, grid, &plane, search.distance).unwrap_or(plane);
    let inliers = grid.count(frame, |p| libm::fabsf(plane.distance(p)) <= search.distance);
    (inliers as f32 >= search.min_share * valid as f32 && inliers >= 3).then_some(FoundPlane {
        plane,
        inliers,
        valid,
    })
}

/// The least-squares plane of the cells within `distance` of `plane`:
/// through their mean, normal along the covariance's smallest
/// eigenvector. Sums are taken relative to the plane's foot point from
/// the sensor, which keeps them small in f32.
fn refit<F: Organised>(frame: &F, grid: &Grid, plane: &Plane, distance: f32) -> Option<Plane> {
    let o = [
        -plane.normal[0] * plane.offset,
        -plane.normal[1] * plane.offset,
        -plane.normal[2] * plane.offset,
    ];
    let mut n = 0u32;
    let mut sum = [0f32; 3];
    let mut products = [[0f32; 3]; 3];
    grid.for_each(frame, |p| {
        if libm::fabsf(plane.distance(p)) > distance {
            return;
        }
        let d = sub(p, o);
        n += 1;
        for i in 0..3 {
            sum[i] += d[i];
            for j in i..3 {
                products[i][j] += d[i] * d[j];
            }
        }
    });
    if n < 3 {
        return None;
    }
    let count = n as f32;
    let mean = [sum[0] / count, sum[1] / count, sum[2] / count];
    let mut covariance = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            covariance[i][j] = products[i][j] / count - mean[i] * mean[j];
        }
    }
    let (_, vectors) = eigen::symmetric(covariance);
    let centre = [o[0] + mean[0], o[1] + mean[1], o[2] + mean[2]];
    Plane::from_normal(vectors[2], centre)
}

pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
