//! A cut single view checked from its sensor's viewpoint.
//!
//! A source that is one object as a depth sensor saw it (the object's side
//! facing the sensor, everything else cut away) says more than its points:
//! where it has no point, the sensor saw past the object. When the
//! viewpoint is known (the sensor's position in the source's frame: the
//! origin for points in a camera's frame), [`View::render`] splats the
//! source into a small depth image seen from there (a z-buffer: each pixel
//! keeps its nearest point's depth), and [`View::check`] verifies a pose
//! against it as [`super::verify`] does against a sensor frame, with one
//! difference: a template point that lands where the view has no depth
//! lies in free space (a violation), not unobserved.
//!
//! So a pose that is reliable by its residual (each source point near the
//! template) must also explain the view the other way: the template's
//! points that face the sensor at that pose lie on the seen surface, and
//! none sticks out of the object's silhouette or in front of it. A
//! one-sided view slid onto the wrong side of the model, or a fragment
//! fitted to part of it, leaves template points in free space.
//!
//! The image: a virtual pinhole camera at the viewpoint, its optical axis
//! through the source's centroid, square pixels sized so that the source's
//! extent spans about `sqrt(n / 2)` of them (`n` its finite points,
//! repeated ones too: about two points a pixel on the object, so its
//! surface has no holes), with
//! half that again of margin on every side, so that a template point off
//! the silhouette lands on an empty pixel rather than outside the image;
//! at most `sqrt(buffer.len())` pixels a side. Each template point is
//! judged on the 3 x 3 pixels about its projection, which bridges a
//! missing pixel. f32 arithmetic through `libm`, in a fixed order:
//! bit-identical on every target. What it catches and misses, measured on
//! ModelNet10 single views: `docs/scene.md`, "A single view checked from
//! its viewpoint".

use super::depth::{Intrinsics, Organised, project};
use super::verify::{Empty, Verification, VerifySettings, tally};
use crate::error::{Error, Result};
use crate::format::Frame;
use crate::pose::Pose;
use crate::template::Template;

/// How far the viewpoint may lie from the source's centroid, in source
/// radii (its farthest finite point from the centroid): a sensor framing
/// an object stands a few radii away; 10,000 leaves f32 depths a
/// resolution finer than a thousandth of the radius.
pub const MAX_DISTANCE: f32 = 10_000.0;

/// The smallest image side [`View::render`] accepts (pixels).
pub const MIN_SIDE: usize = 8;

/// `f32` elements of a buffer for an image of `side` x `side` pixels: 32
/// (4 KB) serves sources up to about 500 points at full resolution;
/// smaller buffers give coarser pixels.
pub const fn buffer_len(side: usize) -> usize {
    side.saturating_mul(side)
}

/// A cut single view rendered from its viewpoint (see the module docs).
/// Its frame is the virtual camera's (x right, y down, z along the optical
/// axis, user units).
#[derive(Debug)]
pub struct View<'b> {
    depth: &'b [f32],
    side: usize,
    intrinsics: Intrinsics,
    /// The camera's axes in the source's frame (rows: x, y, z).
    axes: [[f32; 3]; 3],
    viewpoint: [f32; 3],
}

impl<'b> View<'b> {
    /// Renders `source` (user units) as seen from `viewpoint` (the same
    /// frame) into `buffer`, whose length (at least [`buffer_len`] of
    /// [`MIN_SIDE`]) bounds the image.
    ///
    /// # Errors
    /// [`Error::InvalidOption`] for a non-finite viewpoint, a buffer under
    /// `MIN_SIDE` squared, a viewpoint not in front of every point (at
    /// the source's centroid, or with points beside or behind it) or more
    /// than [`MAX_DISTANCE`] source radii away (a source of one distinct
    /// point has no radius: always); [`Error::EmptyCloud`] without a
    /// finite point.
    pub fn render(source: &[[f32; 3]], viewpoint: [f32; 3], buffer: &'b mut [f32]) -> Result<Self> {
        if !viewpoint.iter().all(|v| v.is_finite()) {
            return Err(Error::InvalidOption {
                what: "the viewpoint must be finite",
            });
        }
        let most = buffer.len().isqrt();
        if most < MIN_SIDE {
            return Err(Error::InvalidOption {
                what: "the view's buffer needs at least 8 x 8 elements",
            });
        }
        let finite = || source.iter().filter(|p| p.iter().all(|v| v.is_finite()));
        let (mut sum, mut n) = ([0f32; 3], 0usize);
        for p in finite() {
            for ((s, v), e) in sum.iter_mut().zip(p).zip(viewpoint) {
                *s += v - e;
            }
            n += 1;
        }
        if n == 0 {
            return Err(Error::EmptyCloud);
        }
        let count = n as f32;
        let offset = sum.map(|s| s / count);
        let axes = camera_axes(offset).ok_or(Error::InvalidOption {
            what: "the viewpoint must not lie at the source's centroid",
        })?;
        // A viewpoint very far from the source (in another frame, such as
        // map coordinates against local ones) would flatten it to one
        // depth in f32 and every pose would pass.
        let centroid = [
            viewpoint[0] + offset[0],
            viewpoint[1] + offset[1],
            viewpoint[2] + offset[2],
        ];
        // One pass: the source's radius, whether every point is in front,
        // and its extent in the image plane (tangents of its angles).
        let (mut radius2, mut behind, mut extent) = (0f32, false, 0f32);
        for p in finite() {
            let d = [p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]];
            radius2 = radius2.max(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            let c = to_camera(&axes, viewpoint, *p);
            behind |= c[2].is_nan() || c[2] <= 0.0;
            extent = extent
                .max(libm::fabsf(c[0] / c[2]))
                .max(libm::fabsf(c[1] / c[2]));
        }
        let distance2 = offset[0] * offset[0] + offset[1] * offset[1] + offset[2] * offset[2];
        if distance2.is_nan() || distance2 > MAX_DISTANCE * MAX_DISTANCE * radius2 {
            return Err(Error::InvalidOption {
                what: "the viewpoint lies more than 10,000 source radii away (is it in the source's frame?)",
            });
        }
        if behind {
            return Err(Error::InvalidOption {
                what: "the viewpoint must see every point in front of it (is it the sensor's position in the source's frame?)",
            });
        }
        // About sqrt(n / 2) pixels across the source, half as many again
        // of margin each side, within the buffer.
        let across = (n / 2).isqrt().max(2);
        let side = (2 * across).min(most).max(MIN_SIDE);
        let across = (side / 2).max(1);
        // Points all on the optical axis (no extent, or a subnormal one):
        // any finite scale.
        let f = across as f32 / (2.0 * extent);
        let f = if f.is_finite() { f } else { 1.0 };
        let centre = (side - 1) as f32 * 0.5;
        let intrinsics = Intrinsics {
            fx: f,
            fy: f,
            cx: centre,
            cy: centre,
        };
        // `side` is at most the buffer's square root: the slice is there.
        let Some(depth) = buffer.get_mut(..side * side) else {
            return Err(Error::InvalidOption {
                what: "the view's buffer needs at least 8 x 8 elements",
            });
        };
        depth.fill(f32::INFINITY);
        for p in finite() {
            let c = to_camera(&axes, viewpoint, *p);
            let Some(([u, v], z)) = project(&intrinsics, c) else {
                continue;
            };
            let (u, v) = (libm::roundf(u), libm::roundf(v));
            if !((0.0..side as f32).contains(&u) && (0.0..side as f32).contains(&v)) {
                continue;
            }
            if let Some(d) = depth.get_mut(v as usize * side + u as usize)
                && z < *d
            {
                *d = z;
            }
        }
        Ok(View {
            depth,
            side,
            intrinsics,
            axes,
            viewpoint,
        })
    }

    /// Pixels a side.
    pub fn side(&self) -> usize {
        self.side
    }

    /// The virtual camera's intrinsics (pixels).
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Checks `pose` (mapping source points onto the template, user units)
    /// against the view: every stored template point of `template` (model
    /// frame `model`) moved into the camera's frame and judged as
    /// [`super::verify::verify`] judges, a point on an empty pixel or off
    /// the image being in free space.
    pub fn check(
        &self,
        template: &Template,
        model: &Frame,
        pose: &Pose,
        settings: &VerifySettings,
    ) -> Verification {
        let back = pose.inverse();
        let points = (0..template.len()).map(|i| {
            let p = back.transform_point(template.user_point(i, model));
            to_camera(&self.axes, self.viewpoint, p)
        });
        tally(
            points,
            self,
            &self.intrinsics,
            settings,
            Empty::FreeSpace,
            None,
        )
    }
}

/// How the models judge a view: [`VerifySettings::for_object`] of the
/// template's radius (user units).
pub(crate) fn settings_for(template: &Template, model: &Frame) -> VerifySettings {
    VerifySettings::for_object(template.radius() / model.scale)
}

/// [`View::render`], then [`View::check`] with the models' settings: what
/// the models' `check_view` do. A pose that is not finite or whose
/// rotation is not a unit quaternion is [`Error::InvalidPose`].
pub(crate) fn check_model(
    template: &Template,
    model: &Frame,
    source: &[[f32; 3]],
    viewpoint: [f32; 3],
    pose: &Pose,
    buffer: &mut [f32],
) -> Result<Verification> {
    let pose = pose.checked_unit()?;
    let view = View::render(source, viewpoint, buffer)?;
    Ok(view.check(template, model, &pose, &settings_for(template, model)))
}

impl Organised for View<'_> {
    fn width(&self) -> usize {
        self.side
    }
    fn height(&self) -> usize {
        self.side
    }
    fn intrinsics(&self) -> Option<Intrinsics> {
        Some(self.intrinsics)
    }
    fn point(&self, u: usize, v: usize) -> Option<[f32; 3]> {
        if u >= self.side || v >= self.side {
            return None;
        }
        let z = *self.depth.get(v * self.side + u)?;
        if !z.is_finite() {
            return None;
        }
        let k = &self.intrinsics;
        Some([
            (u as f32 - k.cx) * z / k.fx,
            (v as f32 - k.cy) * z / k.fy,
            z,
        ])
    }
}

/// A camera looking along `forward` (not normalised): rows x, y, z of a
/// right-handed frame with z along `forward`, x perpendicular to it and to
/// the source frame's x axis (or y, when `forward` is near x), y = z x x.
/// `None` for a zero or non-finite `forward`.
pub(super) fn camera_axes(forward: [f32; 3]) -> Option<[[f32; 3]; 3]> {
    let z = normalised(forward)?;
    let helper = if libm::fabsf(z[0]) < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let x = normalised(cross(z, helper))?;
    let y = cross(z, x);
    Some([x, y, z])
}

/// `p` in the camera's frame.
pub(super) fn to_camera(axes: &[[f32; 3]; 3], viewpoint: [f32; 3], p: [f32; 3]) -> [f32; 3] {
    let d = [
        p[0] - viewpoint[0],
        p[1] - viewpoint[1],
        p[2] - viewpoint[2],
    ];
    axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalised(v: [f32; 3]) -> Option<[f32; 3]> {
    let n = libm::sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    (n.is_finite() && n > 0.0).then(|| v.map(|x| x / n))
}
