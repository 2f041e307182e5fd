//! The template's points on the device: an int16 cloud in the model frame
//! with a uniform grid for exact nearest-neighbour search, used to score a
//! pose (the residual) and to refine it (ICP, [`crate::refine`]).
//!
//! Layout ([`TemplateCloud`]): points sorted by grid cell, one u16 offset
//! per cell. The grid is built on the host by [`build`] and checked once
//! by [`Template::new`] (every point lies in its cell, offsets ascend), so
//! a search never reads outside the blob and the cell bound it relies on is
//! true.
//!
//! Distances are integers (squared int16 steps, `u64`), so the search gives
//! the same neighbour on every target; ties keep the first point met in a
//! fixed visiting order.

use crate::error::{Error, Result};
use crate::format::TemplateCloud;

/// Most cells per axis.
pub const MAX_GRID: u8 = 32;
/// Most template points a blob may hold (offsets are u16).
pub const MAX_POINTS: usize = u16::MAX as usize;

/// A validated view of a blob's [`TemplateCloud`].
#[derive(Debug, Clone)]
pub struct Template<'a> {
    cloud: TemplateCloud<'a>,
    len: usize,
    grid: i32,
}

/// The nearest template point to a query.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Neighbour {
    /// Index of the point (in the blob's sorted order).
    pub index: usize,
    /// Squared distance, in squared int16 steps.
    pub distance_squared: u64,
}

impl<'a> Template<'a> {
    /// Checks a blob's template cloud: at least one point, at most
    /// [`MAX_POINTS`], a grid of 1..=[`MAX_GRID`] cells per axis whose
    /// offsets ascend to the point count, every point inside its cell, a
    /// finite positive step and finite unit turns.
    pub fn new(cloud: TemplateCloud<'a>) -> Result<Self> {
        let bad = |what| Err(Error::InconsistentDimensions { what });
        if !cloud.points.len().is_multiple_of(6) {
            return bad("template points not a multiple of 6 bytes");
        }
        let len = cloud.points.len() / 6;
        if len == 0 || len > MAX_POINTS {
            return bad("template point count outside 1..=65535");
        }
        if !(1..=MAX_GRID).contains(&cloud.grid) || cloud.cell == 0 {
            return bad("template grid size or cell");
        }
        if len.checked_mul(3) != Some(cloud.normals.len()) {
            return bad("template normals: 3 bytes per point");
        }
        for n in cloud.normals.chunks_exact(3) {
            let sq: i32 = n.iter().map(|&v| (v as i8 as i32).pow(2)).sum();
            // 127 x a unit vector, each component rounded: |n|^2 within 10%.
            if !(14_500..=17_800).contains(&sq) {
                return Err(Error::InvalidParameter {
                    what: "template normal is not 127 x a unit vector",
                });
            }
        }
        let grid = cloud.grid as i32;
        let cells = (grid * grid * grid) as usize;
        if cloud.cells.len() != 2 * (cells + 1) {
            return bad("template cell offsets");
        }
        if !(cloud.step.is_finite() && cloud.step > 0.0) {
            return Err(Error::InvalidParameter {
                what: "template step",
            });
        }
        for q in &cloud.turns {
            let n = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
            if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
                return Err(Error::InvalidParameter {
                    what: "template turn is not a unit quaternion",
                });
            }
        }
        let t = Template { cloud, len, grid };
        let mut start = 0usize;
        for c in 0..cells {
            let end = t.offset(c + 1);
            if t.offset(c) != start || end < start || end > len {
                return bad("template cell offsets");
            }
            for i in start..end {
                if t.cell_of(t.point(i)) != Some(c) {
                    return bad("template point outside its cell");
                }
            }
            start = end;
        }
        if start != len {
            return bad("template cell offsets");
        }
        Ok(t)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Always false: a validated template has at least one point.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Model units per int16 step.
    pub fn step(&self) -> f32 {
        self.cloud.step
    }

    /// The symmetry turns stored by the exporter.
    pub fn turns(&self) -> &[[f32; 4]] {
        &self.cloud.turns
    }

    /// Point `i` in int16 steps (zero past the end; indices come from the search).
    pub fn point(&self, i: usize) -> [i32; 3] {
        match self.cloud.points.get(6 * i..6 * i + 6) {
            Some(&[a, b, c, d, e, f]) => [
                i16::from_le_bytes([a, b]) as i32,
                i16::from_le_bytes([c, d]) as i32,
                i16::from_le_bytes([e, f]) as i32,
            ],
            _ => [0; 3],
        }
    }

    /// The normal at point `i`, times 127 (zero past the end).
    pub fn normal(&self, i: usize) -> [i32; 3] {
        match self.cloud.normals.get(3 * i..3 * i + 3) {
            Some(&[a, b, c]) => [a as i8 as i32, b as i8 as i32, c as i8 as i32],
            _ => [0; 3],
        }
    }

    /// How far `q` (int16 steps) lies from the tangent plane at point `i`,
    /// `n . (point_i - q)` in steps (signed), and that unit normal. The dot
    /// product is exact in integers; the one division by `|n|` rounds.
    pub fn plane_offset(&self, i: usize, q: [i32; 3]) -> (f32, [f32; 3]) {
        let (t, ni) = (self.point(i), self.normal(i));
        let norm = libm::sqrtf((ni[0] * ni[0] + ni[1] * ni[1] + ni[2] * ni[2]) as f32);
        let mut dot = 0i64;
        for k in 0..3 {
            dot += (t[k] - q[k]) as i64 * ni[k] as i64;
        }
        (dot as f32 / norm, ni.map(|v| v as f32 / norm))
    }

    /// A model-frame point on the int16 grid, `round(x / step)` by
    /// `libm::roundf`, clamped to `-32767..=32767` (a clamped point is at
    /// least `32767 step - max|template|` away from every template point,
    /// so the clamp only matters beyond any correspondence distance).
    pub fn quantize(&self, p: [f32; 3]) -> [i32; 3] {
        p.map(|x| {
            let r = libm::roundf(x / self.cloud.step);
            // NaN (not produced by finite inputs) maps to 0 via `as`.
            r.clamp(-32767.0, 32767.0) as i32
        })
    }

    fn offset(&self, c: usize) -> usize {
        match self.cloud.cells.get(2 * c..2 * c + 2) {
            Some(&[a, b]) => u16::from_le_bytes([a, b]) as usize,
            _ => 0,
        }
    }

    /// Cell coordinate of a value along an axis whose grid starts at
    /// `origin`, clamped into the grid.
    fn axis_cell(&self, origin: i16, v: i32) -> i32 {
        let rel = v - origin as i32;
        // The cell size is positive (checked at load); `checked_` and
        // `min`/`max` instead of `clamp` leave the compiler no panic path.
        let c = rel.checked_div_euclid(self.cloud.cell as i32).unwrap_or(0);
        c.min(self.grid - 1).max(0)
    }

    /// The cell index of a point, `None` if it lies outside the grid.
    fn cell_of(&self, p: [i32; 3]) -> Option<usize> {
        let mut index = 0usize;
        for (axis, &v) in p.iter().enumerate() {
            let rel = v - self.cloud.origin[axis] as i32;
            let c = rel.checked_div_euclid(self.cloud.cell as i32)?;
            if !(0..self.grid).contains(&c) {
                return None;
            }
            index = index * self.grid as usize + c as usize;
        }
        Some(index)
    }

    /// The nearest template point to `q` (int16 steps) with a squared
    /// distance below `limit`, or `None` if there is none.
    ///
    /// Visits cells in shells of growing Chebyshev radius around `q`'s
    /// (clamped) cell and stops once no unvisited cell can hold a closer
    /// point than the best so far (or than `limit`): exact, not approximate.
    /// Of equally near points it returns the first it visits: the one in
    /// the nearest shell, then with the lowest index.
    pub fn nearest(&self, q: [i32; 3], limit: u64) -> Option<Neighbour> {
        let ([x, y, z], [ox, oy, oz]) = (q, self.cloud.origin);
        let centre = [
            self.axis_cell(ox, x),
            self.axis_cell(oy, y),
            self.axis_cell(oz, z),
        ];
        let mut best: Option<Neighbour> = None;
        let mut bound = limit;
        let g = self.grid;
        let cell = self.cloud.cell as i64;
        // The squared distance from q to the slab of cells `c` along axis
        // `a` (0 inside it), at most `u32::MAX`: a cell's box is at least
        // the sum of its three slabs' away. (The cap can only make a cell
        // look nearer than it is, and visiting a cell that holds no point
        // below the bound changes nothing.)
        let slab = |origin: i16, v: i32, c: i32| -> u32 {
            let lo = origin as i64 + c as i64 * cell;
            let hi = lo + cell - 1;
            let v = v as i64;
            let d = (lo - v).max(v - hi).max(0) as u64;
            (d * d).min(u32::MAX as u64) as u32
        };
        // The y and z slabs of the shell's box, by cell coordinate: each
        // is computed once per shell, not once per cell. (u32: clearing
        // the arrays costs every call.)
        let (mut ys, mut zs) = ([0u32; MAX_GRID as usize], [0u32; MAX_GRID as usize]);
        for r in 0..g {
            let lo = centre.map(|c| (c - r).max(0));
            let hi = centre.map(|c| (c + r).min(g - 1));
            for (slabs, lo, hi, o, v) in [
                (&mut ys, lo[1], hi[1], oy, y),
                (&mut zs, lo[2], hi[2], oz, z),
            ] {
                for c in lo..=hi {
                    if let Some(s) = slabs.get_mut(c as usize) {
                        *s = slab(o, v, c);
                    }
                }
            }
            // The shell's cells (Chebyshev distance `r` from the centre
            // cell) in x, y, z order: every z of the box where x or y is on
            // the shell, else only its two z faces.
            for cx in lo[0]..=hi[0] {
                let sx = slab(ox, x, cx) as u64;
                for cy in lo[1]..=hi[1] {
                    let sxy = sx + ys.get(cy as usize).map_or(0, |&s| s as u64);
                    let on_shell = (cx - centre[0]).abs().max((cy - centre[1]).abs()) == r;
                    let mut visit = |cz: i32| {
                        // Skip a cell that cannot hold a point closer than
                        // the best so far: its box is at least this far.
                        let gap2 = sxy + zs.get(cz as usize).map_or(0, |&s| s as u64);
                        if gap2 < bound {
                            let c = ((cx * g + cy) * g + cz) as usize;
                            self.scan_cell(c, q, &mut bound, &mut best);
                        }
                    };
                    if on_shell {
                        (lo[2]..=hi[2]).for_each(&mut visit);
                    } else {
                        // r >= 1 here: two distinct faces, in z order.
                        for cz in [centre[2] - r, centre[2] + r] {
                            if (lo[2]..=hi[2]).contains(&cz) {
                                visit(cz);
                            }
                        }
                    }
                }
            }
            // Distance from q to the nearest face of the visited box that
            // still has cells beyond it: a lower bound for every unvisited point.
            let mut gap: Option<i64> = None;
            for a in 0..3 {
                let origin = self.cloud.origin[a] as i64;
                if lo[a] > 0 {
                    let face = origin + lo[a] as i64 * cell;
                    gap = Some(gap.map_or(q[a] as i64 - face, |g| g.min(q[a] as i64 - face)));
                }
                if hi[a] < g - 1 {
                    let face = origin + (hi[a] as i64 + 1) * cell;
                    gap = Some(gap.map_or(face - q[a] as i64, |g| g.min(face - q[a] as i64)));
                }
            }
            match gap {
                None => break,
                Some(gap) if gap > 0 && (gap as u64) * (gap as u64) >= bound => break,
                Some(_) => {}
            }
        }
        best
    }

    /// Offers cell `c`'s points to the nearest-point search: a point
    /// strictly nearer than `bound` becomes the best and lowers it.
    #[inline(always)]
    fn scan_cell(&self, c: usize, q: [i32; 3], bound: &mut u64, best: &mut Option<Neighbour>) {
        for i in self.offset(c)..self.offset(c + 1) {
            let d = distance_squared(self.point(i), q);
            if d < *bound {
                *bound = d;
                *best = Some(Neighbour {
                    index: i,
                    distance_squared: d,
                });
            }
        }
    }
}

/// Squared Euclidean distance of two int16-step points (exact in u64).
pub fn distance_squared(a: [i32; 3], b: [i32; 3]) -> u64 {
    let mut d = 0u64;
    for k in 0..3 {
        let e = (a[k] - b[k]).unsigned_abs() as u64;
        d += e * e;
    }
    d
}

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
/// [`Template`]: picks the cell edge so the `grid^3` cells cover the
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::SplitMix64;

    fn brute(points: &[[i16; 3]], q: [i32; 3]) -> u64 {
        points
            .iter()
            .map(|p| distance_squared(p.map(|v| v as i32), q))
            .min()
            .unwrap()
    }

    /// Runs `check` on a template of 300 points on a `grid`-cell grid (at
    /// most 8), every normal along x.
    fn with_template(points: &[[i16; 3]; 300], grid: u8, check: impl FnOnce(&Template<'_>)) {
        let (mut pb, mut nb, mut cb) = ([0u8; 6 * 300], [0u8; 900], [0u8; 2 * (8 * 8 * 8 + 1)]);
        let normals = [[127i8, 0, 0]; 300];
        let out = BuildOut {
            points: &mut pb,
            normals: &mut nb,
            cells: &mut cb,
        };
        let cloud = build(points, &normals, 1e-4, grid, &[], out).unwrap();
        check(&Template::new(cloud).unwrap());
    }

    #[test]
    fn grid_search_is_exact() {
        let mut rng = SplitMix64(3);
        for grid in [1u8, 2, 5, 8] {
            let mut points = [[0i16; 3]; 300];
            for p in points.iter_mut() {
                *p = [0; 3].map(|_: i32| rng.int(-9000, 9000) as i16);
            }
            with_template(&points, grid, |t| {
                assert_eq!(t.len(), 300);
                for _ in 0..500 {
                    let q = [0; 3].map(|_: i32| rng.int(-32767, 32767));
                    let n = t.nearest(q, u64::MAX).unwrap();
                    assert_eq!(n.distance_squared, brute(&points, q));
                    assert_eq!(distance_squared(t.point(n.index), q), n.distance_squared);
                    // With a limit, points at or beyond it are not returned.
                    assert_eq!(t.nearest(q, n.distance_squared), None);
                }
            });
        }
    }

    /// Of equally near points, the search returns the first it visits:
    /// the one whose cell is in the nearest shell around the query's cell,
    /// then the lowest index (points are stored by cell, cells visited in
    /// index order within a shell). Points and queries on a coarse lattice
    /// make many ties; queries also fall outside the grid.
    #[test]
    fn grid_search_breaks_ties_in_visit_order() {
        let mut rng = SplitMix64(5);
        for grid in [1u8, 2, 3, 5, 8] {
            let mut points = [[0i16; 3]; 300];
            for p in points.iter_mut() {
                *p = [0; 3].map(|_: i32| (rng.int(-4, 4) * 1500) as i16);
            }
            with_template(&points, grid, |t| {
                let g = t.grid;
                let cell = |p: [i32; 3]| {
                    let c = t.cell_of(p).unwrap() as i32;
                    [c / (g * g), c / g % g, c % g]
                };
                let (mut ties, mut shells) = (0, 0);
                for _ in 0..400 {
                    let q = [0; 3].map(|_: i32| rng.int(-5, 5) * 1500 + rng.int(-1, 1) * 750);
                    let centre = [0, 1, 2].map(|a| t.axis_cell(t.cloud.origin[a], q[a]));
                    let shell = |i: usize| {
                        let c = cell(t.point(i));
                        (0..3).map(|a| (c[a] - centre[a]).abs()).max().unwrap_or(0)
                    };
                    let n = t.nearest(q, u64::MAX).unwrap();
                    let nearest: std::vec::Vec<usize> = (0..t.len())
                        .filter(|&i| distance_squared(t.point(i), q) == n.distance_squared)
                        .collect();
                    let want = nearest
                        .iter()
                        .copied()
                        .min_by_key(|&i| (shell(i), i))
                        .unwrap();
                    assert_eq!(n.index, want, "grid {grid}, query {q:?}");
                    ties += usize::from(nearest.len() > 1);
                    shells += usize::from(nearest.iter().any(|&i| shell(i) != shell(want)));
                }
                assert!(ties > 100, "grid {grid}: {ties} queries with ties");
                assert!(
                    shells > 0 || grid < 3,
                    "grid {grid}: ties across shells never met"
                );
            });
        }
    }

    #[test]
    fn rejects_inconsistent_clouds() {
        let points = [[0i16, 0, 0], [100, 100, 100], [-50, 20, 7]];
        let (np, nn, nc) = build_len(3, 2);
        let (mut pb, mut nb, mut cb) = ([0u8; 18], [0u8; 9], [0u8; 18]);
        assert_eq!((np, nn, nc), (18, 9, 18));
        let normals = [[0i8, 127, 0], [0, 0, -127], [90, 90, 0]];
        let out = BuildOut {
            points: &mut pb,
            normals: &mut nb,
            cells: &mut cb,
        };
        let cloud = build(&points, &normals, 1e-4, 2, &[[1.0, 0.0, 0.0, 0.0]], out).unwrap();
        assert!(Template::new(cloud.clone()).is_ok());
        // A point moved out of its cell.
        let mut moved = [0u8; 18];
        moved.copy_from_slice(cloud.points);
        moved[0..2].copy_from_slice(&30000i16.to_le_bytes());
        let bad = TemplateCloud {
            points: &moved,
            ..cloud.clone()
        };
        assert!(Template::new(bad).is_err());
        let bad = TemplateCloud {
            step: f32::NAN,
            ..cloud.clone()
        };
        assert!(Template::new(bad).is_err());
        let zero = [0u8; 9];
        let bad = TemplateCloud {
            normals: &zero,
            ..cloud.clone()
        };
        assert!(Template::new(bad).is_err());
        let mut turns = heapless::Vec::new();
        let _ = turns.push([2.0, 0.0, 0.0, 0.0]);
        let bad = TemplateCloud { turns, ..cloud };
        assert!(Template::new(bad).is_err());
    }
}
