//! The template's points a sensor sees at a pose, and a start placed by them.
//!
//! A cut single view holds only the side of the object that faced the
//! sensor, so its centroid is not the object's: it lies towards the
//! sensor, by up to half the object's depth. The network's pose and the
//! turned starts put the source's centroid about where the template's
//! centroid is, so a view's start begins offset along the line of sight,
//! often beyond what ICP pulls back (issue 37: "centre with visibility").
//! [`place`] moves a start's translation so that the source's centroid
//! lands on the centroid of the template points the sensor would see at
//! that start ([`visible_centroid`]); the rotation is kept.
//!
//! Visibility is a coarse z-buffer of the template's stored points, like
//! the experiments' simulated views (`pcrnet_train::view`, whose grid
//! rounds `sqrt(n / 16)` and has no upper bound): the points projected
//! from the sensor's position onto a square grid of [`grid_side`] cells a
//! side (at most [`MAX_GRID`]; 5 for 512 points, about 20 a cell), a point
//! seen when its depth is within one cell's width of its cell's nearest. The
//! stored normals are not used: their sign is arbitrary (estimated by
//! principal components at export). f32 arithmetic in a fixed order, no
//! allocation (a grid of 64 depths on the stack): bit-identical on every
//! target.
//!
//! Measured on the `resampled` experiment's ModelNet10 single-view sets
//! (`docs/scene.md`, "A single view checked from its viewpoint").

use super::view::{camera_axes, to_camera};
use crate::pose::Pose;
use crate::refine::{Guide, Subset};
use crate::template::Template;

/// Most grid cells a side of [`visible_centroid`]'s z-buffer.
pub const MAX_GRID: usize = 8;

/// Fewest grid cells a side.
pub const MIN_GRID: usize = 4;

/// Grid cells a side for `n` stored points: `floor(sqrt(n / 16))` within
/// [`MIN_GRID`]..=[`MAX_GRID`] (512 points: 5).
pub const fn grid_side(n: usize) -> usize {
    let side = (n / 16).isqrt();
    if side < MIN_GRID {
        MIN_GRID
    } else if side > MAX_GRID {
        MAX_GRID
    } else {
        side
    }
}

/// The centroid (the template's model frame) of the template's stored
/// points that a sensor at `eye` looking towards `aim` (both the
/// template's model frame) sees, by the z-buffer of the module docs.
/// `None` when `eye` and `aim` coincide or are not finite, or no stored
/// point lies in front of the sensor.
pub fn visible_centroid(template: &Template<'_>, eye: [f32; 3], aim: [f32; 3]) -> Option<[f32; 3]> {
    let axes = camera_axes([aim[0] - eye[0], aim[1] - eye[1], aim[2] - eye[2]])?;
    let step = template.step();
    let point = |i: usize| template.point(i).map(|v| v as f32 * step);
    // Image-plane coordinates (tangents) and depth; behind the sensor: None.
    let projected = |i: usize| {
        let c = to_camera(&axes, eye, point(i));
        (c[2] > 0.0).then(|| [c[0] / c[2], c[1] / c[2], c[2]])
    };
    let n = template.len();
    let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
    for [x, y, _] in (0..n).filter_map(projected) {
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    if !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
        return None;
    }
    let grid = grid_side(n);
    let side = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f32::MIN_POSITIVE);
    let scale = grid as f32 / side;
    // `as usize` saturates (NaN to 0): the index stays inside the grid.
    let cell = |[x, y, _]: [f32; 3]| {
        let at = |t: f32, lo: f32| (((t - lo) * scale) as usize).min(grid - 1);
        at(y, lo[1]) * grid + at(x, lo[0])
    };
    let mut nearest = [f32::INFINITY; MAX_GRID * MAX_GRID];
    for p in (0..n).filter_map(projected) {
        if let Some(d) = nearest.get_mut(cell(p))
            && p[2] < *d
        {
            *d = p[2];
        }
    }
    // One cell's width at the cell's nearest depth.
    let width = side / grid as f32;
    let (mut sum, mut count) = ([0f32; 3], 0u32);
    for i in 0..n {
        let Some(p) = projected(i) else { continue };
        if nearest
            .get(cell(p))
            .is_some_and(|&near| p[2] <= near + width * near)
        {
            for (s, v) in sum.iter_mut().zip(point(i)) {
                *s += v;
            }
            count += 1;
        }
    }
    (count > 0).then(|| sum.map(|s| s / count as f32))
}

/// `start` (model frame: source onto template) with its translation
/// moved so that `centroid` (the source's centroid, its model frame) lands
/// on the centroid of the template points seen from `eye` (the sensor's
/// position, the source's model frame) at that pose; the rotation is kept,
/// and so is the translation along `keep` (a unit axis of the template's
/// frame, such as the up axis of a start already standing on its plane).
/// Without a visible point, or where the move would give a non-finite
/// translation, the start as it was.
///
/// Once: the sensor's position in the template's frame moves with the
/// translation, but finding the visible points again from the placed start
/// changed nothing that counts (the `resampled` experiment's ModelNet10
/// single-view sets, 200 pairs each, session 51: success 185 / 158 of 200
/// once, 182 / 156 twice and three times; reliable poses more than 5
/// degrees off 4 / 8 once, 3 / 7 twice).
pub fn place(
    template: &Template<'_>,
    start: Pose,
    centroid: [f32; 3],
    eye: [f32; 3],
    keep: Option<[f32; 3]>,
) -> Pose {
    let aim = start.transform_point(centroid);
    let Some(seen) = visible_centroid(template, start.transform_point(eye), aim) else {
        return start;
    };
    let mut d = [seen[0] - aim[0], seen[1] - aim[1], seen[2] - aim[2]];
    if let Some(k) = keep {
        let along = d[0] * k[0] + d[1] * k[1] + d[2] * k[2];
        d = [
            d[0] - along * k[0],
            d[1] - along * k[1],
            d[2] - along * k[2],
        ];
    }
    let t = &start.translation;
    let moved = [t[0] + d[0], t[1] + d[1], t[2] + d[2]];
    if moved.iter().all(|v| v.is_finite()) {
        Pose {
            translation: moved,
            ..start
        }
    } else {
        start
    }
}

/// A [`Guide`] that places every start by what a sensor at a known
/// viewpoint sees ([`place`]), and lets every screened start finish.
#[derive(Debug, Clone, Copy)]
pub struct Placing<'a, 't> {
    template: &'a Template<'t>,
    centroid: [f32; 3],
    eye: [f32; 3],
    keep: Option<[f32; 3]>,
}

impl<'a, 't> Placing<'a, 't> {
    /// For the used points of `subset` seen from `viewpoint` (the source's
    /// frame, user units), keeping the translation along `keep` (see
    /// [`place`]).
    pub fn new(
        template: &'a Template<'t>,
        subset: &Subset<'_>,
        viewpoint: [f32; 3],
        keep: Option<[f32; 3]>,
    ) -> Self {
        Placing {
            template,
            centroid: subset.centroid(),
            eye: subset.frame.to_model(viewpoint),
            keep,
        }
    }
}

impl Guide for Placing<'_, '_> {
    fn place(&mut self, start: Pose) -> Pose {
        place(self.template, start, self.centroid, self.eye, self.keep)
    }
}
