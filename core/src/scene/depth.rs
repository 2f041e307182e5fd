//! Organised frames: a depth image read in place, or an organised cloud.
//!
//! A sensor frame is a grid of `width x height` pixels, row `v` from the
//! top and column `u` from the left, each holding one point in the
//! **sensor frame** (x right, y down, z forward along the optical axis,
//! user units) or nothing where the sensor saw nothing. Both forms are
//! borrowed, never copied: a pixel becomes a point when a stage reads it.
//!
//! - [`DepthImage`]: 16-bit depth (`&[u16]`, a row stride, pinhole
//!   [`Intrinsics`], a depth scale and an invalid value), as RGB-D and
//!   time-of-flight sensors give it. A pixel's point is the pinhole back
//!   projection (Hartley & Zisserman, *Multiple View Geometry*, 6.1):
//!   `z = raw * depth_scale`, `x = (u - cx) * z / fx`, `y = (v - cy) * z / fy`,
//!   single f32 operations in that order, so every target computes the same bits.
//! - [`OrganisedPoints`]: points already in the sensor frame, one per
//!   pixel in row order, non-finite where the sensor saw nothing (an
//!   organised PCD, `HEIGHT > 1`).

use crate::error::{Error, Result};

/// A frame the scene stages can read pixel by pixel.
pub trait Organised {
    /// Pixels per row.
    fn width(&self) -> usize;
    /// Rows.
    fn height(&self) -> usize;
    /// The point seen at column `u`, row `v` (sensor frame, user units),
    /// or `None` where the sensor saw nothing or `(u, v)` is outside the frame.
    fn point(&self, u: usize, v: usize) -> Option<[f32; 3]>;
    /// How sensor-frame points project to pixels, when known: what
    /// verification against the frame ([`super::verify`]) needs.
    fn intrinsics(&self) -> Option<Intrinsics>;
}

/// Pinhole intrinsics in pixels: focal lengths `fx`, `fy` and the
/// principal point `(cx, cy)`, pixel centres at integer coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Intrinsics {
    /// Focal length along u (pixels).
    pub fx: f32,
    /// Focal length along v (pixels).
    pub fy: f32,
    /// Principal point, column.
    pub cx: f32,
    /// Principal point, row.
    pub cy: f32,
}

/// A borrowed 16-bit depth image.
#[derive(Debug, Clone, Copy)]
pub struct DepthImage<'a> {
    depth: &'a [u16],
    width: usize,
    height: usize,
    stride: usize,
    intrinsics: Intrinsics,
    depth_scale: f32,
    invalid: u16,
    // 1 / fx and 1 / fy, computed once.
    inverse_f: [f32; 2],
}

impl<'a> DepthImage<'a> {
    /// Views `depth` as `height` rows of `width` pixels, `stride` values
    /// apart (`stride >= width`; the last row needs only `width` values).
    /// A raw value `r` is at depth `r * depth_scale` user units (0.001 for
    /// millimetres read as metres); pixels equal to `invalid` (and 0, which
    /// no sensor reports as a depth) hold no point.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for a zero width or height, a stride below
    /// the width, a slice shorter than the frame, focal lengths that are
    /// not finite and positive, a non-finite principal point, or a depth
    /// scale that is not finite and positive.
    pub fn new(
        depth: &'a [u16],
        width: usize,
        height: usize,
        stride: usize,
        intrinsics: Intrinsics,
        depth_scale: f32,
        invalid: u16,
    ) -> Result<Self> {
        let bad = |what| Err(Error::InvalidFrame { what });
        if width == 0 || height == 0 {
            return bad("width and height must be at least 1");
        }
        if stride < width {
            return bad("the row stride must be at least the width");
        }
        let needed = (height - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(width));
        if needed.is_none_or(|n| depth.len() < n) {
            return bad("the depth slice is shorter than height rows of the stride");
        }
        let Intrinsics { fx, fy, cx, cy } = intrinsics;
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !positive(fx) || !positive(fy) {
            return bad("focal lengths fx and fy must be finite and > 0");
        }
        if !cx.is_finite() || !cy.is_finite() {
            return bad("the principal point must be finite");
        }
        if !positive(depth_scale) {
            return bad("the depth scale must be finite and > 0");
        }
        Ok(DepthImage {
            depth,
            width,
            height,
            stride,
            intrinsics,
            depth_scale,
            invalid,
            inverse_f: [1.0 / fx, 1.0 / fy],
        })
    }

    /// The intrinsics the image was made with.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// The raw value at column `u`, row `v` (`None` outside the frame).
    pub fn raw(&self, u: usize, v: usize) -> Option<u16> {
        if u >= self.width || v >= self.height {
            return None;
        }
        self.depth.get(v * self.stride + u).copied()
    }

    /// Projects a sensor-frame point to its pixel `(u, v)` (real-valued,
    /// pixel centres at integers) and depth `z`; `None` behind the sensor.
    pub fn project(&self, p: [f32; 3]) -> Option<([f32; 2], f32)> {
        project(&self.intrinsics, p)
    }

    /// The depth in user units of a raw value, `None` if it holds no point.
    pub fn depth_of(&self, raw: u16) -> Option<f32> {
        if raw == self.invalid || raw == 0 {
            None
        } else {
            Some(raw as f32 * self.depth_scale)
        }
    }
}

/// Pinhole projection of `p` (sensor frame) to `([u, v], z)`; `None` when
/// `z` is not positive.
pub fn project(k: &Intrinsics, p: [f32; 3]) -> Option<([f32; 2], f32)> {
    let z = p[2];
    if z.is_nan() || z <= 0.0 {
        return None;
    }
    Some(([k.fx * p[0] / z + k.cx, k.fy * p[1] / z + k.cy], z))
}

impl Organised for DepthImage<'_> {
    fn width(&self) -> usize {
        self.width
    }
    fn height(&self) -> usize {
        self.height
    }
    fn intrinsics(&self) -> Option<Intrinsics> {
        Some(self.intrinsics)
    }
    fn point(&self, u: usize, v: usize) -> Option<[f32; 3]> {
        let z = self.depth_of(self.raw(u, v)?)?;
        let k = &self.intrinsics;
        let x = (u as f32 - k.cx) * z * self.inverse_f[0];
        let y = (v as f32 - k.cy) * z * self.inverse_f[1];
        Some([x, y, z])
    }
}

/// An organised cloud: `width x height` points in row order, in the
/// sensor frame; a point with a non-finite coordinate holds nothing.
#[derive(Debug, Clone, Copy)]
pub struct OrganisedPoints<'a> {
    points: &'a [[f32; 3]],
    width: usize,
    height: usize,
    intrinsics: Option<Intrinsics>,
}

impl<'a> OrganisedPoints<'a> {
    /// Views `points` as rows of `width`.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for a zero width, or a length that is zero
    /// or not a multiple of the width.
    pub fn new(points: &'a [[f32; 3]], width: usize) -> Result<Self> {
        if width == 0 || points.is_empty() || !points.len().is_multiple_of(width) {
            return Err(Error::InvalidFrame {
                what: "an organised cloud needs a width >= 1 dividing its point count",
            });
        }
        Ok(OrganisedPoints {
            points,
            width,
            height: points.len() / width,
            intrinsics: None,
        })
    }

    /// The same cloud, its projection known (for verification).
    pub fn with_intrinsics(self, intrinsics: Intrinsics) -> Self {
        OrganisedPoints {
            intrinsics: Some(intrinsics),
            ..self
        }
    }

    /// The pinhole intrinsics that best explain where the points lie: for
    /// a pinhole, `u = fx x / z + cx` and `v = fy y / z + cy`, so each is a
    /// least-squares line fit (f64 sums in row order) over every 4th
    /// pixel of every 4th row holding a point in front of the sensor.
    /// `None` when fewer than 16 such points or a fit is degenerate.
    pub fn estimate_intrinsics(&self) -> Option<Intrinsics> {
        let mut n = 0f64;
        let mut sums = [[0f64; 4]; 2]; // per axis: a, pixel, a^2, a * pixel
        for v in (0..self.height).step_by(4) {
            for u in (0..self.width).step_by(4) {
                let Some(p) = self.point(u, v) else {
                    continue;
                };
                if p[2] <= 0.0 {
                    continue;
                }
                n += 1.0;
                let z = f64::from(p[2]);
                let [x, y] = &mut sums;
                for (s, a, pixel) in [(x, p[0], u), (y, p[1], v)] {
                    let a = f64::from(a) / z;
                    let pixel = pixel as f64;
                    s[0] += a;
                    s[1] += pixel;
                    s[2] += a * a;
                    s[3] += a * pixel;
                }
            }
        }
        if n < 16.0 {
            return None;
        }
        let fit = |s: [f64; 4]| {
            let variance = n * s[2] - s[0] * s[0];
            let f = (n * s[3] - s[0] * s[1]) / variance;
            let c = (s[1] - f * s[0]) / n;
            (f.is_finite() && f > 0.0 && c.is_finite()).then_some((f as f32, c as f32))
        };
        let [x, y] = sums;
        let (fx, cx) = fit(x)?;
        let (fy, cy) = fit(y)?;
        Some(Intrinsics { fx, fy, cx, cy })
    }
}

impl Organised for OrganisedPoints<'_> {
    fn width(&self) -> usize {
        self.width
    }
    fn height(&self) -> usize {
        self.height
    }
    fn intrinsics(&self) -> Option<Intrinsics> {
        self.intrinsics
    }
    fn point(&self, u: usize, v: usize) -> Option<[f32; 3]> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let p = *self.points.get(v * self.width + u)?;
        p.iter().all(|c| c.is_finite()).then_some(p)
    }
}
