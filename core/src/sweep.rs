//! Starting poses for an object standing on a surface, seen from one side.
//!
//! The network's hypotheses cover the turns it was trained on (the paper's
//! ±45°) about a source centred on its centroid; a one-sided view of an
//! object standing on a table in any yaw is outside both. When the surface
//! is known (the plane of [`crate::scene::plane`], sensor frame) and the
//! template's up axis is given (the axis pointing away from the surface it
//! rests on, template frame), the pose is fixed up to a turn about the
//! plane's normal and a shift along the plane. The starts are:
//!
//! - rotation: the plane's normal turned onto the up axis (the shortest
//!   arc), then `k / yaws` of a full turn about the up axis, `k = 0..yaws`;
//! - translation: the source's points on the plane land on the template's
//!   lowest level along the up axis (its base), and the source's centroid
//!   over the template's centre along the plane (a view from one side sees
//!   the near half: ICP slides the rest). [`crate::locate`], which knows
//!   where the sensor stands, then moves each start along the plane so the
//!   source's centroid is over the centroid of what the sensor would see of
//!   the template there ([`crate::scene::visible`]).
//!
//! Each start gets the screening ICP, the best the full ICP
//! ([`crate::refine::resolve_starts`]); the network is not run (this is
//! the classical multi-start model fit; the network's own hypotheses need
//! a full view near its trained range). With 12 yaws the right one is
//! within 15 degrees, where ICP converges.

use crate::error::{Error, Result};
use crate::format::Frame;
use crate::pose::Pose;
use crate::refine::Subset;
use crate::scene::{DEFAULT_YAWS, Plane};
use crate::template::Template;

/// Most yaw starts.
pub const MAX_YAWS: usize = 360;

/// A surface the object stands on and the template's up axis.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sweep {
    /// The surface, in the source's frame (user units; its normal towards
    /// the side the object stands on, as [`crate::scene::plane::find`] turns
    /// it towards the sensor).
    pub plane: Plane,
    /// The template's up axis (template frame, any length).
    pub up: [f32; 3],
    /// Yaw starts, evenly spread over a full turn (1..=[`MAX_YAWS`]).
    pub yaws: usize,
}

impl Sweep {
    /// [`DEFAULT_YAWS`] starts on `plane` with the template's `up`.
    pub fn new(plane: Plane, up: [f32; 3]) -> Self {
        Sweep {
            plane,
            up,
            yaws: DEFAULT_YAWS,
        }
    }

    /// Checks the axis, the plane and the yaw count.
    ///
    /// # Errors
    /// [`Error::InvalidOption`] naming what is wrong.
    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |what| Err(Error::InvalidOption { what });
        if !(1..=MAX_YAWS).contains(&self.yaws) {
            return bad("a sweep needs 1 to 360 yaws");
        }
        let n = self.plane.normal;
        let unit = dot(n, n);
        if !(self.plane.offset.is_finite() && (unit - 1.0).abs() <= 1e-3) {
            return bad("the sweep's plane needs a unit normal and a finite offset");
        }
        let u = dot(self.up, self.up);
        if !(u.is_finite() && u > 0.0) {
            return bad("the up axis must be finite and not zero");
        }
        Ok(())
    }
}

/// A blob's up axis ([`crate::format::Trailer::up`]) when it is a finite
/// unit vector (within 1e-3 of unit length, as the exporter writes it).
///
/// # Errors
/// [`Error::InconsistentDimensions`] naming the axis otherwise.
pub(crate) fn checked_up(up: Option<[f32; 3]>) -> Result<Option<[f32; 3]>> {
    match up {
        Some(u) if !(u.iter().all(|v| v.is_finite()) && libm::fabsf(dot(u, u) - 1.0) <= 1e-3) => {
            Err(Error::InconsistentDimensions {
                what: "the template's up axis must be a finite unit vector",
            })
        }
        u => Ok(u),
    }
}

/// The sweep's up axis at unit length (template frame).
pub(crate) fn unit_up(sweep: &Sweep) -> [f32; 3] {
    let length = libm::sqrtf(dot(sweep.up, sweep.up));
    sweep.up.map(|v| v / length)
}

/// The sweep's starts in the model frame, numbered from 0.
pub(crate) fn starts(
    frame: &Frame,
    template: &Template<'_>,
    subset: &Subset<'_>,
    sweep: &Sweep,
) -> impl Iterator<Item = (usize, Pose)> {
    let n = sweep.plane.normal;
    let up = unit_up(sweep);
    let align = shortest_arc(n, up);
    // The plane in the model frame: n . p_m + offset_m = 0.
    let offset = frame.scale * (sweep.plane.offset + dot(n, frame.centre));
    // The template's base: its lowest level along the up axis (model units).
    let step = template.step();
    let base = (0..template.len())
        .map(|i| dot(template.point(i).map(|q| q as f32 * step), up))
        .fold(f32::INFINITY, f32::min);
    let centroid = subset.centroid();
    let yaws = sweep.yaws.max(1);
    (0..yaws).map(move |k| {
        let half = core::f32::consts::PI * k as f32 / yaws as f32;
        let (s, c) = (libm::sinf(half), libm::cosf(half));
        let yaw = [c, s * up[0], s * up[1], s * up[2]];
        let rotation = product(yaw, align);
        let turn = Pose {
            rotation,
            translation: [0.0; 3],
        };
        // -R c_m, its part along the up axis replaced so that the plane
        // lands on the base: u . t = base + offset.
        let moved = turn.transform_point(centroid);
        let along = dot(moved, up);
        let lift = base + offset + along;
        let translation = [
            -moved[0] + up[0] * lift,
            -moved[1] + up[1] * lift,
            -moved[2] + up[2] * lift,
        ];
        (
            k,
            Pose {
                rotation,
                translation,
            },
        )
    })
}

/// The unit quaternion of the shortest turn taking unit `from` onto unit
/// `to`: `[1 + from . to, from x to]` normalised; for opposite vectors a
/// half turn about an axis perpendicular to `from`.
fn shortest_arc(from: [f32; 3], to: [f32; 3]) -> [f32; 4] {
    let w = 1.0 + dot(from, to);
    let [x, y, z] = cross(from, to);
    let q = if w > 1e-6 {
        [w, x, y, z]
    } else {
        // Half turn: about whichever axis is least along `from`.
        let other = if libm::fabsf(from[0]) < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let [x, y, z] = cross(from, other);
        [0.0, x, y, z]
    };
    let norm = libm::sqrtf(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    q.map(|v| v / norm)
}

/// The Hamilton product `a b`: the turn `b`, then `a`.
fn product(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
