//! From the 7 head outputs to a rigid transform.
//!
//! The head outputs `[qw, qx, qy, qz, tx, ty, tz]`. The quaternion is
//! normalised by its Euclidean norm (`libm::sqrtf`) and made canonical with
//! `qw >= 0` (q and -q are the same rotation). The pose maps the **source
//! onto the template**: `p_template ~= R p_source + t`.
//!
//! All of this is f32 arithmetic with single IEEE-754 operations (no fused
//! multiply-add: Rust never contracts) and `libm` called explicitly, so the
//! result is bit-identical on x86_64 and thumbv7em.

use crate::arch::POSE_DIM;
use crate::error::{Error, Result};
use crate::format::Frame;

/// Rotation quaternions whose squared norm is further than this from 1
/// are refused as an input pose ([`Pose::checked_unit`]).
pub const UNIT_TOLERANCE: f32 = 1e-3;

/// A rigid transform: unit quaternion (scalar first) and translation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose {
    /// Unit quaternion `[w, x, y, z]` with `w >= 0`.
    pub rotation: [f32; 4],
    /// Translation `[x, y, z]`.
    pub translation: [f32; 3],
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Pose = Pose {
        rotation: [1.0, 0.0, 0.0, 0.0],
        translation: [0.0; 3],
    };

    /// Builds a pose from raw head outputs `[qw, qx, qy, qz, tx, ty, tz]`.
    ///
    /// Fails with [`Error::DegeneratePose`] when the quaternion's norm is not
    /// a positive finite number or a translation is not finite.
    pub fn from_head_output(raw: &[f32; POSE_DIM]) -> Result<Pose> {
        let [w, x, y, z, tx, ty, tz] = *raw;
        let n = libm::sqrtf(w * w + x * x + y * y + z * z);
        if !(n.is_finite() && n > 0.0 && tx.is_finite() && ty.is_finite() && tz.is_finite()) {
            return Err(Error::DegeneratePose);
        }
        let s = if w < 0.0 { -1.0 / n } else { 1.0 / n };
        Ok(Pose {
            rotation: [w * s, x * s, y * s, z * s],
            translation: [tx, ty, tz],
        })
    }

    /// The 3x3 rotation matrix, row-major.
    pub fn rotation_matrix(&self) -> [[f32; 3]; 3] {
        let [w, x, y, z] = self.rotation;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// The 4x4 homogeneous matrix, row-major.
    pub fn matrix(&self) -> [[f32; 4]; 4] {
        let r = self.rotation_matrix();
        let t = self.translation;
        [
            [r[0][0], r[0][1], r[0][2], t[0]],
            [r[1][0], r[1][1], r[1][2], t[1]],
            [r[2][0], r[2][1], r[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// Applies the transform to a point: `R p + t`. (To move many points,
    /// build a [`Rigid`] once.)
    pub fn transform_point(&self, p: [f32; 3]) -> [f32; 3] {
        Rigid::from(self).apply(p)
    }

    /// `self` followed by `next`: the pose `p -> next(self(p))`.
    ///
    /// The quaternion product is made canonical (`w >= 0`) but not
    /// renormalised: a product of unit quaternions drifts by a few ulp at
    /// most over the 20 compositions of an iterative registration, and this
    /// way `Pose::IDENTITY.then(p)` is `p` bit for bit.
    pub fn then(&self, next: &Pose) -> Pose {
        let [aw, ax, ay, az] = next.rotation;
        let [bw, bx, by, bz] = self.rotation;
        let q = [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ];
        let rotation = if q[0] < 0.0 { q.map(|v| -v) } else { q };
        Pose {
            rotation,
            translation: next.transform_point(self.translation),
        }
    }

    /// The inverse transform, `p -> R^T (p - t)`: `self.then(&self.inverse())`
    /// is the identity up to rounding.
    pub fn inverse(&self) -> Pose {
        let [w, x, y, z] = self.rotation;
        let back = Pose {
            rotation: [w, -x, -y, -z],
            translation: [0.0; 3],
        };
        let [tx, ty, tz] = back.transform_point(self.translation);
        Pose {
            rotation: back.rotation,
            translation: [-tx, -ty, -tz],
        }
    }

    /// The same pose with its quaternion scaled to unit length (by
    /// `libm::sqrtf`, `w >= 0`): compositions drift from unit length by a
    /// few ulp each, and a pose carried from frame to frame composes
    /// without end. A zero or non-finite quaternion is returned as is.
    pub fn normalised(&self) -> Pose {
        let [w, x, y, z] = self.rotation;
        let n = libm::sqrtf(w * w + x * x + y * y + z * z);
        if !(n.is_finite() && n > 0.0) {
            return *self;
        }
        let s = if w < 0.0 { -1.0 / n } else { 1.0 / n };
        Pose {
            rotation: [w * s, x * s, y * s, z * s],
            translation: self.translation,
        }
    }

    /// This pose as an input may be given (a previous pose to track from,
    /// a pose to check): finite, its rotation within [`UNIT_TOLERANCE`]
    /// of unit length, then [`Self::normalised`]; else
    /// [`Error::InvalidPose`].
    pub fn checked_unit(&self) -> Result<Pose> {
        let [w, x, y, z] = self.rotation;
        let norm = w * w + x * x + y * y + z * z;
        if !(self.is_finite() && libm::fabsf(norm - 1.0) <= UNIT_TOLERANCE) {
            return Err(Error::InvalidPose);
        }
        Ok(self.normalised())
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation
            .iter()
            .chain(&self.translation)
            .all(|v| v.is_finite())
    }

    /// `|q . q_other|`, the cosine of half the angle between the two
    /// rotations (1: the same rotation; the quaternions' signs do not matter).
    pub fn rotation_cosine(&self, other: &Pose) -> f32 {
        let dot: f32 = self
            .rotation
            .iter()
            .zip(other.rotation)
            .map(|(a, b)| a * b)
            .sum();
        libm::fabsf(dot)
    }

    /// `||T - I||_F^2` of the 4x4 matrix: how far the pose is from the identity.
    pub fn distance_to_identity_squared(&self) -> f32 {
        let r = self.rotation_matrix();
        let mut d = 0.0;
        for (i, row) in r.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                let e = if i == j { v - 1.0 } else { v };
                d += e * e;
            }
        }
        self.translation.iter().fold(d, |d, t| d + t * t)
    }
}

/// A pose as a rotation matrix and a translation, to move many points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid {
    /// Rotation, row-major.
    pub rotation: [[f32; 3]; 3],
    /// Translation.
    pub translation: [f32; 3],
}

impl From<&Pose> for Rigid {
    fn from(pose: &Pose) -> Self {
        Rigid {
            rotation: pose.rotation_matrix(),
            translation: pose.translation,
        }
    }
}

impl Rigid {
    /// `R p + t`, each row summed left to right.
    pub fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        let (r, t) = (&self.rotation, &self.translation);
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + t[0],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + t[1],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + t[2],
        ]
    }
}

impl Frame {
    /// A user-unit point in the model frame: `(p - centre) * scale`, per axis.
    pub fn to_model(&self, p: [f32; 3]) -> [f32; 3] {
        let ([x, y, z], [cx, cy, cz], s) = (p, self.centre, self.scale);
        [(x - cx) * s, (y - cy) * s, (z - cz) * s]
    }

    /// A model-frame point in user units, the inverse of [`Frame::to_model`]:
    /// `p / scale + centre`, per axis.
    pub fn to_user(&self, p: [f32; 3]) -> [f32; 3] {
        let ([x, y, z], [cx, cy, cz], s) = (p, self.centre, self.scale);
        [x / s + cx, y / s + cy, z / s + cz]
    }

    /// A pose between model-frame clouds as a pose between user-unit
    /// clouds: with `N(p) = s (p - c)`, `N^-1 . P . N` keeps `R` and has
    /// `t = t_model / s + c - R c`.
    pub fn pose_to_user(&self, pose: &Pose) -> Pose {
        let [rx, ry, rz] = self.turned_centre(pose);
        let ([tx, ty, tz], [cx, cy, cz], s) = (pose.translation, self.centre, self.scale);
        Pose {
            rotation: pose.rotation,
            translation: [tx / s + cx - rx, ty / s + cy - ry, tz / s + cz - rz],
        }
    }

    /// A pose between user-unit clouds as a pose between model-frame
    /// clouds, the inverse of [`Frame::pose_to_user`]: `R` kept,
    /// `t_model = s (t - c + R c)`.
    pub fn pose_to_model(&self, pose: &Pose) -> Pose {
        let [rx, ry, rz] = self.turned_centre(pose);
        let ([tx, ty, tz], [cx, cy, cz], s) = (pose.translation, self.centre, self.scale);
        Pose {
            rotation: pose.rotation,
            translation: [(tx - cx + rx) * s, (ty - cy + ry) * s, (tz - cz + rz) * s],
        }
    }

    /// `R c`: the frame's centre turned by `pose`'s rotation.
    fn turned_centre(&self, pose: &Pose) -> [f32; 3] {
        let r = Pose {
            rotation: pose.rotation,
            translation: [0.0; 3],
        };
        r.transform_point(self.centre)
    }
}

/// The pose one frame on at constant velocity: with `before` and `last`
/// the poses of the two previous frames (each mapping that frame's source
/// onto the template), the motion between them, `V = last . before^-1`
/// in the template's frame, applied once more: `V . last`. Exact for an
/// object moving (or a sensor moving about it) at a constant rigid velocity
/// between frames taken at a constant rate.
///
/// The quaternion is renormalised ([`Pose::normalised`]): the prediction
/// composes three poses, and a stream predicts from its own predictions.
pub fn predict(before: &Pose, last: &Pose) -> Pose {
    let velocity = before.inverse().then(last);
    last.then(&velocity).normalised()
}

/// How a source point is moved before the network or the template search:
/// from user units into the model frame ([`Frame::to_model`]), then by a
/// pose in that frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointMap {
    /// User units -> model frame.
    pub frame: Frame,
    /// The pose applied in the model frame.
    pub rigid: Rigid,
}

impl PointMap {
    /// Into `frame`, then by `pose`.
    pub fn new(frame: Frame, pose: &Pose) -> Self {
        PointMap {
            frame,
            rigid: Rigid::from(pose),
        }
    }

    /// `pose(frame(p))`.
    pub fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        self.rigid.apply(self.frame.to_model(p))
    }
}

/// The centroid of a cloud, accumulated in f64 (IEEE-754 on every target:
/// hardware on the host, correctly rounded soft-float on Cortex-M4) and
/// rounded to f32 once. The f64 sum of f32 coordinates is exact, so the
/// result does not depend on the order of the points, while the largest
/// magnitude over the smallest non-zero one stays below `2^29 / N`.
pub fn centroid(points: &[[f32; 3]]) -> Result<[f32; 3]> {
    if points.is_empty() {
        return Err(Error::EmptyCloud);
    }
    let mut sum = [0f64; 3];
    for (index, p) in points.iter().enumerate() {
        if p.iter().any(|x| !x.is_finite()) {
            return Err(Error::NonFiniteCoordinate { index });
        }
        for (s, &x) in sum.iter_mut().zip(p) {
            *s += x as f64;
        }
    }
    let n = points.len() as f64;
    Ok(sum.map(|s| (s / n) as f32))
}

/// How a network expects its source placed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Centring {
    /// As given (in the model frame).
    None,
    /// Centred on its centroid, computed over the points within `radius`
    /// (model units, per axis) of a robust centre ([`robust_centroid`]):
    /// the int8 path's input range, so that a stray point the encoder
    /// leaves out does not move the centre either; infinite on the f32
    /// path (every point).
    Centroid {
        /// Per-axis distance from the robust centre, model units.
        radius: f32,
    },
}

/// Points whose coordinate-wise median is the robust centre of
/// [`robust_centroid`] (a stride sample, sorted on the stack).
pub const MEDIAN_SAMPLE: usize = 31;

/// The centroid ([`centroid`]) of the points within `radius` (per axis,
/// user units) of a robust centre: the coordinate-wise median of a stride
/// sample of at most [`MEDIAN_SAMPLE`] points. A cloud whose points all lie
/// within `radius` of it gives exactly [`centroid`]'s value; far stray
/// points (fewer than half the sample) are left out instead of pulling the
/// centre towards them. If no point is within `radius` (impossible for a
/// cloud with at most a few outliers), every point counts.
pub fn robust_centroid(points: &[[f32; 3]], radius: f32) -> Result<[f32; 3]> {
    if points.is_empty() {
        return Err(Error::EmptyCloud);
    }
    if let Some(index) = points.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::NonFiniteCoordinate { index });
    }
    let stride = points.len().div_ceil(MEDIAN_SAMPLE).max(1);
    let mut median = [0f32; 3];
    for (axis, m) in median.iter_mut().enumerate() {
        let mut sample = [0f32; MEDIAN_SAMPLE];
        let mut n = 0;
        for (slot, p) in sample.iter_mut().zip(points.iter().step_by(stride)) {
            if let Some(&x) = p.get(axis) {
                *slot = x;
                n += 1;
            }
        }
        *m = lower_median(sample.split_at(n.min(MEDIAN_SAMPLE)).0);
    }
    let near = |p: &[f32; 3]| {
        p.iter()
            .zip(&median)
            .all(|(&x, &m)| libm::fabsf(x - m) <= radius)
    };
    let (mut sum, mut n) = ([0f64; 3], 0usize);
    for p in points.iter().filter(|p| near(p)) {
        for (s, &x) in sum.iter_mut().zip(p) {
            *s += x as f64;
        }
        n += 1;
    }
    if n == 0 {
        return centroid(points);
    }
    let n = n as f64;
    Ok(sum.map(|s| (s / n) as f32))
}

/// The lower median (the `(n - 1) / 2`-th smallest) of finite values, by
/// counting rather than sorting (no index arithmetic, no allocation; n is
/// at most [`MEDIAN_SAMPLE`]); 0 for none.
fn lower_median(values: &[f32]) -> f32 {
    let k = values.len().saturating_sub(1) / 2;
    values
        .iter()
        .copied()
        .find(|&v| {
            let less = values.iter().filter(|&&x| x < v).count();
            let not_more = values.iter().filter(|&&x| x <= v).count();
            less <= k && k < not_more
        })
        .unwrap_or(0.0)
}

/// Where registration starts, in the model frame: the identity, or for a
/// network trained on centred sources (as the reference PCRNet
/// implementation does), the translation by minus the source's centroid
/// ([`robust_centroid`] with the radius of `centring`, in user units, then
/// moved into the model frame). The network then sees the centred source,
/// and composing its estimate after this pose gives the pose of the source
/// as given.
pub fn centring(points: &[[f32; 3]], centring: Centring, frame: &Frame) -> Result<Pose> {
    let Centring::Centroid { radius } = centring else {
        return Ok(Pose::IDENTITY);
    };
    let c = frame.to_model(robust_centroid(points, radius / frame.scale)?);
    Ok(Pose {
        rotation: Pose::IDENTITY.rotation,
        translation: [-c[0], -c[1], -c[2]],
    })
}

/// Iterative registration (i-PCRNet at test time): from `start`, each
/// step estimates the pose of the source moved by the current estimate, and
/// the estimates compose (`current.then(delta)`). Stops after `iterations`
/// steps, or earlier once a step's `||delta - I||_F` is below `tolerance`
/// (the paper uses 1e-7 and 20 iterations). Returns the pose and the number
/// of steps taken.
pub fn iterate(
    start: Pose,
    iterations: usize,
    tolerance: f32,
    mut step: impl FnMut(&Pose) -> Result<Pose>,
) -> Result<(Pose, usize)> {
    let mut current = start;
    for done in 1..=iterations {
        let delta = step(&current)?;
        current = current.then(&delta);
        if delta.distance_to_identity_squared() < tolerance * tolerance {
            return Ok((current, done));
        }
    }
    Ok((current, iterations))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalises_and_canonicalises() {
        let p = Pose::from_head_output(&[-2.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(p.rotation, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(p.transform_point([1.0, 1.0, 1.0]), [2.0, 3.0, 4.0]);
    }

    #[test]
    fn quarter_turn_about_z() {
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let p = Pose::from_head_output(&[h, 0.0, 0.0, h, 0.0, 0.0, 0.0]).unwrap();
        let q = p.transform_point([1.0, 0.0, 0.0]);
        assert!((q[0]).abs() < 1e-6 && (q[1] - 1.0).abs() < 1e-6 && q[2].abs() < 1e-6);
        let m = p.matrix();
        assert_eq!(m[3], [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn composition_applies_first_then_second() {
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let a = Pose::from_head_output(&[h, 0.0, 0.0, h, 1.0, 0.0, 0.0]).unwrap();
        let b = Pose::from_head_output(&[h, h, 0.0, 0.0, 0.0, 2.0, 0.0]).unwrap();
        let p = [0.3, -0.7, 1.1];
        let composed = a.then(&b).transform_point(p);
        let stepwise = b.transform_point(a.transform_point(p));
        for k in 0..3 {
            assert!((composed[k] - stepwise[k]).abs() < 1e-5);
        }
        assert_eq!(Pose::IDENTITY.distance_to_identity_squared(), 0.0);
        assert!((a.distance_to_identity_squared() - (2.0 + 2.0 + 1.0)).abs() < 1e-5);
    }

    #[test]
    fn iterate_composes_and_stops_early() {
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let quarter = Pose::from_head_output(&[h, 0.0, 0.0, h, 0.0, 0.0, 0.0]).unwrap();
        let mut calls = 0;
        let (pose, n) = iterate(Pose::IDENTITY, 20, 1e-3, |_| {
            calls += 1;
            Ok(if calls <= 2 { quarter } else { Pose::IDENTITY })
        })
        .unwrap();
        assert_eq!((n, calls), (3, 3));
        // Two quarter turns about z: a half turn.
        let p = pose.transform_point([1.0, 0.0, 0.0]);
        assert!((p[0] + 1.0).abs() < 1e-5 && p[1].abs() < 1e-5);
        assert_eq!(
            iterate(Pose::IDENTITY, 5, 0.0, |_| Err(Error::EmptyCloud)),
            Err(Error::EmptyCloud)
        );
    }

    #[test]
    fn the_lower_median_counts_instead_of_sorting() {
        assert_eq!(lower_median(&[3.0, 1.0, 2.0, 2.0]), 2.0);
        assert_eq!(lower_median(&[5.0, 1.0]), 1.0);
        assert_eq!(lower_median(&[-0.0, 0.0, 7.0]), 0.0);
        assert_eq!(lower_median(&[]), 0.0);
    }

    #[test]
    fn centring_moves_the_centroid_to_the_origin() {
        let pts = [[1.0, 2.0, 3.0], [3.0, 2.0, 1.0]];
        assert_eq!(centroid(&pts), Ok([2.0, 2.0, 2.0]));
        let all = Centring::Centroid {
            radius: f32::INFINITY,
        };
        let c = centring(&pts, all, &Frame::IDENTITY).unwrap();
        assert_eq!(c.transform_point([2.0, 2.0, 2.0]), [0.0; 3]);
        assert_eq!(
            centring(&pts, Centring::None, &Frame::IDENTITY),
            Ok(Pose::IDENTITY)
        );
        let frame = Frame {
            centre: [1.0, 1.0, 1.0],
            scale: 0.5,
        };
        let c = centring(&pts, all, &frame).unwrap();
        assert_eq!(c.transform_point(frame.to_model([2.0, 2.0, 2.0])), [0.0; 3]);
        assert_eq!(centroid(&[]), Err(Error::EmptyCloud));
        assert_eq!(
            centroid(&[[0.0; 3], [f32::NAN, 0.0, 0.0]]),
            Err(Error::NonFiniteCoordinate { index: 1 })
        );
    }

    #[test]
    fn frame_round_trips_poses() {
        let frame = Frame {
            centre: [3.0, -2.0, 10.0],
            scale: 0.05,
        };
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let model = Pose::from_head_output(&[h, 0.0, h, 0.0, 0.3, -0.2, 0.1]).unwrap();
        let user = frame.pose_to_user(&model);
        for p in [[1.0f32, 2.0, 3.0], [-4.0, 0.5, 12.0]] {
            let lhs = frame.to_model(user.transform_point(p));
            let rhs = model.transform_point(frame.to_model(p));
            for k in 0..3 {
                assert!((lhs[k] - rhs[k]).abs() < 1e-5, "{lhs:?} vs {rhs:?}");
            }
        }
    }

    #[test]
    fn degenerate_outputs_are_errors() {
        assert_eq!(
            Pose::from_head_output(&[0.0; 7]),
            Err(Error::DegeneratePose)
        );
        assert_eq!(
            Pose::from_head_output(&[1.0, 0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0]),
            Err(Error::DegeneratePose)
        );
        assert_eq!(
            Pose::from_head_output(&[f32::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            Err(Error::DegeneratePose)
        );
    }
}
