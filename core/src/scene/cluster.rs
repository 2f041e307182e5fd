//! Clusters: connected components of the sampling grid's foreground, and
//! the points of one cluster gathered at full resolution.
//!
//! A cell is **foreground** when it holds a point that is not on the
//! plane (farther than `plane_distance` from it on the sensor's side;
//! cells behind the plane, seen past its edge, are background too). Two
//! foreground cells side by side or one above the other join when their
//! points are at most `max_gap` apart: Euclidean clustering restricted to
//! grid neighbours, as connected-component segmentation of organised
//! clouds does (Trevor et al., *Efficient Organized Point Cloud
//! Segmentation with Connected Components*, 2013). Components are found
//! with union-find in the caller's label slice, each joined to the smaller
//! of the two roots, so a cluster's label is the number of its first cell
//! in row order and the labelling is the same on every target.

use heapless::Vec;

use super::depth::Organised;
use super::grid::{Cell, Grid};
use super::plane::{Plane, sub};
use crate::error::{Error, Result};

/// Label of a cell that holds no point, lies outside the region of
/// interest, or is on or behind the plane.
pub const BACKGROUND: u16 = u16::MAX;

/// Most clusters measured and reported per frame: the largest ones.
pub const MAX_CLUSTERS: usize = 16;

/// How clusters are formed and which are kept.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClusterSearch {
    /// Neighbouring cells join when their points are at most this far apart
    /// (user units).
    pub max_gap: f32,
    /// A cell within this distance of the plane is on it (user units).
    pub plane_distance: f32,
    /// Clusters of fewer cells are noise.
    pub min_cells: u32,
    /// A cluster is kept when its radius (the largest distance of its
    /// cells' points from their mean, which no turn of the object changes)
    /// lies in `[radius[0], radius[1]]` (user units).
    pub radius: [f32; 2],
}

/// One cluster: its label, its cells and where it lies.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Cluster {
    /// Its label: the number of its first cell in row order.
    pub label: u16,
    /// Cells in it.
    pub cells: u32,
    /// Smallest x, y, z of its cells' points (sensor frame).
    pub min: [f32; 3],
    /// Largest x, y, z.
    pub max: [f32; 3],
    /// Mean of its cells' points.
    pub centroid: [f32; 3],
    /// Largest distance of its cells' points from `centroid`.
    pub radius: f32,
    /// Grid columns and rows it spans: `[first column, first row, last column, last row]`.
    pub span: [u16; 4],
}

/// The clusters of one frame: those kept, largest first, and why the
/// others were dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct Clusters {
    /// Clusters whose extent fits, largest first (ties: lower label first).
    pub kept: Vec<Cluster, MAX_CLUSTERS>,
    /// Foreground cells.
    pub foreground: u32,
    /// Clusters under `min_cells`.
    pub too_few_cells: u32,
    /// Clusters whose radius is outside `radius`.
    pub wrong_radius: u32,
    /// Clusters of enough cells left unmeasured beyond the [`MAX_CLUSTERS`] largest.
    pub unmeasured: u32,
}

/// Labels every cell of `grid` into `labels` (length at least
/// `2 * grid.cells()`: the labels, then the component sizes) and measures
/// the largest clusters.
///
/// # Errors
/// [`Error::BufferTooSmall`] when `labels` is shorter than `2 * grid.cells()`.
pub fn label<F: Organised>(
    frame: &F,
    grid: &Grid,
    plane: Option<&Plane>,
    search: &ClusterSearch,
    labels: &mut [u16],
) -> Result<Clusters> {
    let cells = grid.cells();
    let needed = 2 * cells;
    if labels.len() < needed {
        return Err(Error::BufferTooSmall {
            needed: needed * 2,
            available: labels.len() * 2,
        });
    }
    let (roots, rest) = labels.split_at_mut(cells.min(labels.len()));
    let sizes = rest.get_mut(..cells).unwrap_or_default();
    let foreground = |p: [f32; 3]| plane.is_none_or(|pl| pl.distance(p) > search.plane_distance);
    let columns = grid.columns();
    let cell_point = |gx: usize, gy: usize| grid.point(frame, gx, gy).filter(|&p| foreground(p));
    let joins = |a: [f32; 3], b: [f32; 3]| joins(a, b, search.max_gap);

    // Union-find: every foreground cell starts as its own root; a cell's
    // parent is never a later cell.
    roots.fill(BACKGROUND);
    grid.for_each_cell(frame, |cell, p| {
        if !foreground(p) {
            return;
        }
        let Cell { index, gx, gy } = cell;
        if let Some(slot) = roots.get_mut(index) {
            *slot = index as u16;
        }
        let left = (gx > 0).then(|| (index - 1, gx - 1, gy));
        let up = (gy > 0).then(|| (index - columns, gx, gy - 1));
        for (n, nx, ny) in [left, up].into_iter().flatten() {
            if roots.get(n).is_none_or(|&r| r == BACKGROUND) {
                continue;
            }
            if cell_point(nx, ny).is_some_and(|q| joins(p, q)) {
                let (a, b) = (find(roots, index), find(roots, n));
                let (low, high) = if a < b { (a, b) } else { (b, a) };
                if let Some(slot) = roots.get_mut(high) {
                    *slot = low as u16;
                }
            }
        }
    });
    // Flatten (parents come first, so one pass in order suffices) and count.
    sizes.fill(0);
    let mut count = 0u32;
    for index in 0..cells {
        let Some(&parent) = roots.get(index) else {
            break;
        };
        if parent == BACKGROUND {
            continue;
        }
        let root = roots.get(usize::from(parent)).copied().unwrap_or(parent);
        roots[index] = root;
        if let Some(size) = sizes.get_mut(usize::from(root)) {
            *size = size.saturating_add(1);
        }
        count += 1;
    }

    // The largest components of enough cells.
    let mut clusters = Clusters {
        kept: Vec::new(),
        foreground: count,
        too_few_cells: 0,
        wrong_radius: 0,
        unmeasured: 0,
    };
    let mut largest: Vec<(u16, u16), MAX_CLUSTERS> = Vec::new();
    for (index, (&root, &size)) in roots.iter().zip(sizes.iter()).enumerate() {
        if usize::from(root) != index {
            continue;
        }
        if u32::from(size) < search.min_cells {
            clusters.too_few_cells += 1;
            continue;
        }
        let entry = (size, index as u16);
        if largest.push(entry).is_err() {
            clusters.unmeasured += 1;
            // Replace the smallest (the last of equal sizes) if this one is larger.
            if let Some(slot) = smallest(&largest).and_then(|at| largest.get_mut(at))
                && slot.0 < size
            {
                *slot = entry;
            }
        }
    }
    // Largest first, then by label: an insertion sort of at most
    // MAX_CLUSTERS entries (the slice sorts keep a panic path for
    // inconsistent orders, which the no-panic proof refuses).
    for i in 1..largest.len() {
        let mut j = i;
        while j > 0 {
            let (Some(&a), Some(&b)) = (largest.get(j - 1), largest.get(j)) else {
                break;
            };
            if (b.0, core::cmp::Reverse(b.1)) <= (a.0, core::cmp::Reverse(a.1)) {
                break;
            }
            largest.swap(j - 1, j);
            j -= 1;
        }
    }

    // Measure them.
    let mut measured: Vec<Cluster, MAX_CLUSTERS> = Vec::new();
    for &(size, root) in &largest {
        let _ = measured.push(Cluster {
            label: root,
            cells: u32::from(size),
            min: [f32::INFINITY; 3],
            max: [f32::NEG_INFINITY; 3],
            centroid: [0.0; 3],
            radius: 0.0,
            span: [u16::MAX, u16::MAX, 0, 0],
        });
    }
    grid.for_each_cell(frame, |cell, p| {
        let Some(&root) = roots.get(cell.index) else {
            return;
        };
        let Some(c) = measured.iter_mut().find(|c| c.label == root) else {
            return;
        };
        for (i, &x) in p.iter().enumerate() {
            c.min[i] = c.min[i].min(x);
            c.max[i] = c.max[i].max(x);
            c.centroid[i] += x;
        }
        let (gx, gy) = (cell.gx as u16, cell.gy as u16);
        c.span = [
            c.span[0].min(gx),
            c.span[1].min(gy),
            c.span[2].max(gx),
            c.span[3].max(gy),
        ];
    });
    for mut c in measured {
        let n = c.cells as f32;
        c.centroid = [c.centroid[0] / n, c.centroid[1] / n, c.centroid[2] / n];
        c.radius = radius(frame, grid, roots, &c);
        if c.radius >= search.radius[0] && c.radius <= search.radius[1] {
            let _ = clusters.kept.push(c);
        } else {
            clusters.wrong_radius += 1;
        }
    }
    Ok(clusters)
}

/// Whether neighbouring cells' points `a` and `b` belong together: at
/// most `max_gap` plus twice the lateral spacing of their pixels apart.
/// The spacing, `|a / a.z - b / b.z| * min(a.z, b.z)`, grows with depth
/// as a pinhole's pixels do and needs no intrinsics; twice it lets a
/// surface turned up to 60 degrees from the sensor stay connected.
fn joins(a: [f32; 3], b: [f32; 3], max_gap: f32) -> bool {
    let d = sub(a, b);
    let distance2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if !(a[2] > 0.0 && b[2] > 0.0) {
        return distance2 <= max_gap * max_gap;
    }
    let rx = a[0] / a[2] - b[0] / b[2];
    let ry = a[1] / a[2] - b[1] / b[2];
    let spacing = libm::sqrtf(rx * rx + ry * ry) * a[2].min(b[2]);
    let allowed = max_gap + 2.0 * spacing;
    distance2 <= allowed * allowed
}

/// The largest distance of `cluster`'s cells' points from its centroid.
fn radius<F: Organised>(frame: &F, grid: &Grid, labels: &[u16], cluster: &Cluster) -> f32 {
    let [c0, r0, c1, r1] = cluster.span.map(usize::from);
    let columns = grid.columns();
    let mut largest = 0f32;
    for gy in r0..=r1 {
        for gx in c0..=c1 {
            if labels.get(gy * columns + gx) != Some(&cluster.label) {
                continue;
            }
            if let Some(p) = grid.point(frame, gx, gy) {
                let d = sub(p, cluster.centroid);
                largest = largest.max(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            }
        }
    }
    libm::sqrtf(largest)
}

/// The root of `index`, halving the path on the way.
fn find(roots: &mut [u16], mut index: usize) -> usize {
    loop {
        let Some(&parent) = roots.get(index) else {
            return index;
        };
        let parent = usize::from(parent);
        if parent == index {
            return index;
        }
        let grandparent = roots.get(parent).copied().unwrap_or(parent as u16);
        roots[index] = grandparent;
        index = usize::from(grandparent);
    }
}

/// Where the smallest entry is (the last of equal sizes).
fn smallest(entries: &[(u16, u16)]) -> Option<usize> {
    entries
        .iter()
        .enumerate()
        .rev()
        .min_by_key(|(_, e)| e.0)
        .map(|(i, _)| i)
}

/// Writes the points of `cluster` at full resolution into `out`: every
/// pixel of its cells that holds a foreground point joining its cell's
/// point (as neighbouring cells join), cells in row order and pixels in row order within a
/// cell. When there are more than `out.len()`, every k-th is taken
/// (`k = ceil(count / out.len())`). Returns how many were written.
pub fn gather<F: Organised>(
    frame: &F,
    grid: &Grid,
    plane: Option<&Plane>,
    search: &ClusterSearch,
    labels: &[u16],
    cluster: &Cluster,
    out: &mut [[f32; 3]],
) -> usize {
    if out.is_empty() {
        return 0;
    }
    let mut count = 0usize;
    visit(frame, grid, plane, search, labels, cluster, |_| count += 1);
    let every = count.div_ceil(out.len()).max(1);
    let (mut seen, mut written) = (0usize, 0usize);
    visit(frame, grid, plane, search, labels, cluster, |p| {
        if seen % every == 0
            && let Some(slot) = out.get_mut(written)
        {
            *slot = p;
            written += 1;
        }
        seen += 1;
    });
    written
}

/// Calls `f` on every point [`gather`] takes, in its order.
fn visit<F: Organised>(
    frame: &F,
    grid: &Grid,
    plane: Option<&Plane>,
    search: &ClusterSearch,
    labels: &[u16],
    cluster: &Cluster,
    mut f: impl FnMut([f32; 3]),
) {
    let [c0, r0, c1, r1] = cluster.span.map(usize::from);
    let (step, columns) = (grid.step(), grid.columns());
    for gy in r0..=r1.min(grid.rows().saturating_sub(1)) {
        for gx in c0..=c1.min(columns.saturating_sub(1)) {
            let index = gy * columns + gx;
            if labels.get(index) != Some(&cluster.label) {
                continue;
            }
            let Some(centre) = grid.point(frame, gx, gy) else {
                continue;
            };
            for v in gy * step..(gy + 1) * step {
                for u in gx * step..(gx + 1) * step {
                    let Some(p) = frame.point(u, v) else {
                        continue;
                    };
                    let near = joins(p, centre, search.max_gap);
                    let above = plane.is_none_or(|pl| pl.distance(p) > search.plane_distance);
                    if near && above && grid.admits(p) {
                        f(p);
                    }
                }
            }
        }
    }
}
