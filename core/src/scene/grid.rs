//! The sampling grid the scene stages work on: every `step`-th pixel of
//! every `step`-th row, inside an optional region of interest.
//!
//! Cell `(gx, gy)` samples pixel `(gx * step, gy * step)` and stands for
//! the `step x step` pixels below and right of it; cells are numbered in
//! row order, `gy * columns + gx`. A cell holds a point when its pixel
//! does and the point lies in the region of interest.

use super::depth::Organised;
use crate::error::{Error, Result};

/// An axis-aligned box in the sensor frame (user units), bounds included.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Region {
    /// Smallest x, y, z.
    pub min: [f32; 3],
    /// Largest x, y, z.
    pub max: [f32; 3],
}

impl Region {
    /// Whether `p` lies in the box.
    pub fn contains(&self, p: [f32; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}

/// Most cells a grid may have: labels are `u16`, and two values are
/// reserved (see [`super::cluster`]).
pub const MAX_CELLS: usize = u16::MAX as usize - 2;

/// One cell: its number in row order, its column and its row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cell {
    /// `gy * columns + gx`.
    pub index: usize,
    /// Column.
    pub gx: usize,
    /// Row.
    pub gy: usize,
}

/// A sampling grid over one frame's size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    step: usize,
    columns: usize,
    rows: usize,
    roi: Option<Region>,
}

impl Grid {
    /// The grid of every `step`-th pixel of a `width x height` frame.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for a zero step, a zero frame size, a region
    /// of interest with a non-finite or reversed bound, or more than
    /// [`MAX_CELLS`] cells (take a larger step).
    pub fn new(width: usize, height: usize, step: usize, roi: Option<Region>) -> Result<Self> {
        let bad = |what| Err(Error::InvalidFrame { what });
        if step == 0 {
            return bad("the sampling step must be at least 1");
        }
        if width == 0 || height == 0 {
            return bad("width and height must be at least 1");
        }
        if let Some(r) = roi {
            let ordered = (0..3)
                .all(|i| r.min[i].is_finite() && r.max[i].is_finite() && r.min[i] <= r.max[i]);
            if !ordered {
                return bad("the region of interest needs finite bounds with min <= max");
            }
        }
        let columns = width.div_ceil(step);
        let rows = height.div_ceil(step);
        if columns.checked_mul(rows).is_none_or(|n| n > MAX_CELLS) {
            return bad("the sampling grid has more than 65,533 cells: take a larger step");
        }
        Ok(Grid {
            step,
            columns,
            rows,
            roi,
        })
    }

    /// The grid of every `step`-th pixel of `frame`.
    ///
    /// # Errors
    /// As [`Grid::new`].
    pub fn over<F: Organised>(frame: &F, step: usize, roi: Option<Region>) -> Result<Self> {
        Grid::new(frame.width(), frame.height(), step, roi)
    }

    /// Pixels between samples.
    pub fn step(&self) -> usize {
        self.step
    }
    /// Cells per row.
    pub fn columns(&self) -> usize {
        self.columns
    }
    /// Rows of cells.
    pub fn rows(&self) -> usize {
        self.rows
    }
    /// Cells in all.
    pub fn cells(&self) -> usize {
        self.columns * self.rows
    }
    /// The region of interest, if any.
    pub fn roi(&self) -> Option<Region> {
        self.roi
    }

    /// Whether `p` is inside the region of interest (always, without one).
    pub fn admits(&self, p: [f32; 3]) -> bool {
        self.roi.is_none_or(|r| r.contains(p))
    }

    /// The point of the cell in column `gx`, row `gy`, if it holds one.
    pub fn point<F: Organised>(&self, frame: &F, gx: usize, gy: usize) -> Option<[f32; 3]> {
        if gx >= self.columns || gy >= self.rows {
            return None;
        }
        let p = frame.point(gx * self.step, gy * self.step)?;
        self.admits(p).then_some(p)
    }

    /// Calls `f(cell, point)` for every cell holding a point, in row order.
    pub fn for_each_cell<F: Organised>(&self, frame: &F, mut f: impl FnMut(Cell, [f32; 3])) {
        let mut index = 0;
        for gy in 0..self.rows {
            for gx in 0..self.columns {
                if let Some(p) = frame.point(gx * self.step, gy * self.step)
                    && self.admits(p)
                {
                    f(Cell { index, gx, gy }, p);
                }
                index += 1;
            }
        }
    }

    /// Calls `f(point)` for every cell holding a point, in row order.
    pub fn for_each<F: Organised>(&self, frame: &F, mut f: impl FnMut([f32; 3])) {
        self.for_each_cell(frame, |_, p| f(p));
    }

    /// Cells holding a point for which `keep` is true.
    pub fn count<F: Organised>(&self, frame: &F, mut keep: impl FnMut([f32; 3]) -> bool) -> u32 {
        let mut n = 0u32;
        self.for_each(frame, |p| n += u32::from(keep(p)));
        n
    }
}
