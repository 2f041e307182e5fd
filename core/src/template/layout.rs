//! Laying out a template for [`Template`](super::Template) (on the host, or wherever a
//! template is made): the grid's cell edge, points and normals sorted by
//! cell, and the cell offsets.

use super::{MAX_GRID, MAX_POINTS};
use crate::error::{Error, Result};
use crate::format::TemplateCloud;

/// Bytes [`build`] writes for `points` points on a `grid^3` grid:
/// `(points bytes, normals bytes, cell offset bytes)`.
pub const fn build_len(points: usize, grid: u8) -> (usize, usize, usize) {
    let g = grid as usize;
    (6 * points, 3 * points, 2 * (g * g * g + 1))
}

/// Where [`build`] writes: points, normals and cell offsets (sizes from [`build_len`]).
#[derive(Debug)]
pub struct BuildOut<'o> {
    /// Points, 6 bytes each.
    pub points: &'o mut [u8],
    /// Normals, 3 bytes each.
    pub normals: &'o mut [u8],
    /// Cell offsets.
    pub cells: &'o mut [u8],
}

/// Lays out quantized template points and their normals (127 x unit) for
/// [`Template`](super::Template): picks the cell edge so the `grid^3` cells cover the
/// points' bounding box, sorts points and normals by cell (counting sort,
/// stable, no allocation) into `out` and writes the cell offsets. Returns
/// the [`TemplateCloud`] borrowing `out`.
pub fn build<'o>(
    points: &[[i16; 3]],
    normals: &[[i8; 3]],
    step: f32,
    grid: u8,
    turns: &[[f32; 4]],
    out: BuildOut<'o>,
) -> Result<TemplateCloud<'o>> {
    if normals.len() != points.len() {
        return Err(Error::InconsistentDimensions {
            what: "template normals: one per point",
        });
    }
    let BuildOut {
        points: points_out,
        normals: normals_out,
        cells: cells_out,
    } = out;
    if points.is_empty() || points.len() > MAX_POINTS {
        return Err(Error::InconsistentDimensions {
            what: "template point count outside 1..=65535",
        });
    }
    if !(1..=MAX_GRID).contains(&grid) {
        return Err(Error::InvalidParameter {
            what: "template grid outside 1..=32",
        });
    }
    let (np, nn, nc) = build_len(points.len(), grid);
    for (needed, available) in [
        (np, points_out.len()),
        (nn, normals_out.len()),
        (nc, cells_out.len()),
    ] {
        if available < needed {
            return Err(Error::BufferTooSmall { needed, available });
        }
    }
    let turns = heapless::Vec::from_slice(turns).map_err(|_| Error::InvalidParameter {
        what: "more template turns than MAX_TURNS",
    })?;
    let mut lo = [i32::MAX; 3];
    let mut hi = [i32::MIN; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] as i32);
            hi[k] = hi[k].max(p[k] as i32);
        }
    }
    let g = grid as i32;
    let span = (0..3).map(|k| hi[k] - lo[k] + 1).max().unwrap_or(1);
    // ceil(span / g), at least 1.
    let cell = ((span + g - 1) / g).max(1);
    let origin = lo.map(|v| v as i16);
    let cell_of = |p: &[i16; 3]| -> usize {
        let mut index = 0usize;
        for k in 0..3 {
            let c = ((p[k] as i32 - lo[k]) / cell).min(g - 1);
            index = index * g as usize + c as usize;
        }
        index
    };
    let cells = (g * g * g) as usize;
    let cells_out = &mut cells_out[..nc];
    cells_out.fill(0);
    let read = |b: &[u8], c: usize| u16::from_le_bytes([b[2 * c], b[2 * c + 1]]);
    // Counts in slot c + 1, then prefix sums: slot c = start of cell c.
    for p in points {
        let c = cell_of(p) + 1;
        let v = read(cells_out, c) + 1;
        cells_out[2 * c..2 * c + 2].copy_from_slice(&v.to_le_bytes());
    }
    for c in 1..=cells {
        let v = read(cells_out, c) + read(cells_out, c - 1);
        cells_out[2 * c..2 * c + 2].copy_from_slice(&v.to_le_bytes());
    }
    // Place each point at its cell's cursor (slot c, advanced), then shift
    // the cursors back into starts.
    let points_out = &mut points_out[..np];
    let normals_out = &mut normals_out[..nn];
    for (p, n) in points.iter().zip(normals) {
        let c = cell_of(p);
        let at = read(cells_out, c) as usize;
        for k in 0..3 {
            points_out[6 * at + 2 * k..6 * at + 2 * k + 2].copy_from_slice(&p[k].to_le_bytes());
            normals_out[3 * at + k] = n[k] as u8;
        }
        cells_out[2 * c..2 * c + 2].copy_from_slice(&(at as u16 + 1).to_le_bytes());
    }
    for c in (1..=cells).rev() {
        let v = read(cells_out, c - 1);
        cells_out[2 * c..2 * c + 2].copy_from_slice(&v.to_le_bytes());
    }
    cells_out[..2].copy_from_slice(&0u16.to_le_bytes());
    let cloud = TemplateCloud {
        step,
        points: points_out,
        normals: normals_out,
        grid,
        origin,
        cell: cell as u16,
        cells: cells_out,
        turns,
    };
    Ok(cloud)
}
