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
//! A format-4 blob also carries a closest-point table ([`NearestTable`],
//! module `table`): where it covers a query, the search reads the
//! query's cell's short list of candidates instead of walking the grid,
//! and finds the same point.
//!
//! Distances are integers (squared int16 steps, `u64`), so the search gives
//! the same neighbour on every target; ties keep the first point met in a
//! fixed visiting order.

use crate::error::{Error, Result};
use crate::format::{Frame, NearestTable, TemplateCloud};

mod layout;
mod table;
pub use layout::{BuildOut, build, build_len};
use table::Table;
pub use table::{MAX_TABLE_CELLS, TableShape, build_table, table_len, table_work_len};

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
    table: Option<Table<'a>>,
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
    /// finite positive step and finite unit turns; and its closest-point
    /// table if there is one (see [`NearestTable`]).
    pub fn new(cloud: TemplateCloud<'a>, table: Option<NearestTable<'a>>) -> Result<Self> {
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
        let table = table.map(|t| Table::new(t, cloud.points)).transpose()?;
        let t = Template {
            cloud,
            len,
            grid,
            table,
        };
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

    /// The closest-point table, if the blob has one.
    pub fn table(&self) -> Option<NearestTable<'a>> {
        self.table.map(|t| t.stored())
    }

    /// The template as a blob stores it: its cloud.
    pub fn cloud(&self) -> &TemplateCloud<'a> {
        &self.cloud
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

    /// The largest distance of a stored point from the model frame's
    /// origin (the template's centre), model units.
    pub fn radius(&self) -> f32 {
        let largest = (0..self.len)
            .map(|i| {
                let q = self.point(i).map(i64::from);
                (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]) as u64
            })
            .max()
            .unwrap_or(0);
        libm::sqrtf(largest as f32) * self.cloud.step
    }

    /// Point `i` in user units: `q * step / scale + centre` with the blob's
    /// `frame`, each axis a product and a sum in f32.
    pub fn user_point(&self, i: usize, frame: &Frame) -> [f32; 3] {
        let step = self.cloud.step / frame.scale;
        let q = self.point(i);
        [
            q[0] as f32 * step + frame.centre[0],
            q[1] as f32 * step + frame.centre[1],
            q[2] as f32 * step + frame.centre[2],
        ]
    }

    /// The symmetry turns stored by the exporter.
    pub fn turns(&self) -> &[[f32; 4]] {
        &self.cloud.turns
    }

    /// Point `i` in int16 steps (zero past the end; indices come from the search).
    pub fn point(&self, i: usize) -> [i16; 3] {
        self.cloud
            .points
            .get(6 * i..6 * i + 6)
            .map_or([0; 3], stored_point)
    }

    /// The normal at point `i`, times 127 (zero past the end).
    pub fn normal(&self, i: usize) -> [i32; 3] {
        match self.cloud.normals.get(3 * i..3 * i + 3) {
            Some(&[a, b, c]) => [a as i8 as i32, b as i8 as i32, c as i8 as i32],
            _ => [0; 3],
        }
    }

    /// How far `q` (int16 steps) lies from the tangent plane at point `i`,
    /// `n . (point_i - q)` in steps (signed), and that unit normal: the
    /// [`Self::stored_plane_offset`] divided by the stored normal's length
    /// (one `libm::sqrtf`, four divisions, each rounding once).
    pub fn plane_offset(&self, i: usize, q: [i16; 3]) -> (f32, [f32; 3]) {
        let (dot, n) = self.stored_plane_offset(i, q);
        let norm = libm::sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        (dot / norm, n.map(|v| v / norm))
    }

    /// [`Self::plane_offset`] with the normal as stored (127 times a unit
    /// vector, each component rounded: `|m|^2` between 14,500 and 17,800,
    /// checked at load, so `|m| / 127` lies in 0.948..1.051) instead of the
    /// unit normal: `m . (point_i - q)`
    /// and `m`, exact (the dot product in integers).
    #[inline(always)]
    pub fn stored_plane_offset(&self, i: usize, q: [i16; 3]) -> (f32, [f32; 3]) {
        let (t, m) = (self.point(i), self.normal(i));
        // Exact in i32: |t - q| <= 65534 and |m| <= 128 per axis, so the
        // sum is at most 3 x 65534 x 128 < 2^25 (and converts to f32 with
        // one instruction, where an i64 takes a library call on the M4).
        let mut dot = 0i32;
        for k in 0..3 {
            dot += (t[k] as i32 - q[k] as i32) * m[k];
        }
        (dot as f32, m.map(|v| v as f32))
    }

    /// A model-frame point on the int16 grid, `round(x / step)` (half away
    /// from zero, [`crate::fixed::round_clamped_i16`]), clamped to
    /// `-32767..=32767` (a clamped point is at least `32767 step -
    /// max|template|` away from every template point, so the clamp only
    /// matters beyond any correspondence distance). NaN (not produced by
    /// finite inputs) maps to 0.
    pub fn quantize(&self, p: [f32; 3]) -> [i16; 3] {
        p.map(|x| crate::fixed::round_clamped_i16(x / self.cloud.step))
    }

    fn offset(&self, c: usize) -> usize {
        match self.cloud.cells.get(2 * c..2 * c + 2) {
            Some(&[a, b]) => u16::from_le_bytes([a, b]) as usize,
            _ => 0,
        }
    }

    /// Cell coordinate of a value along an axis whose grid starts at
    /// `origin`, clamped into the grid.
    fn axis_cell(&self, origin: i32, v: i32) -> i32 {
        let rel = v - origin;
        // The cell size is positive (checked at load); `checked_` and
        // `min`/`max` instead of `clamp` leave the compiler no panic path.
        let c = rel.checked_div_euclid(self.cloud.cell as i32).unwrap_or(0);
        c.min(self.grid - 1).max(0)
    }

    /// The cell index of a point, `None` if it lies outside the grid.
    fn cell_of(&self, p: [i16; 3]) -> Option<usize> {
        let mut index = 0usize;
        for (axis, &v) in p.iter().enumerate() {
            let rel = v as i32 - self.cloud.origin[axis] as i32;
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
    ///
    /// Where the closest-point table covers `q`, the candidates of its
    /// cell are scanned instead: the same point, ties broken alike.
    ///
    /// All of it is i32 arithmetic but the squared distances (`SMULL` /
    /// `SMLAL` on a Cortex-M4): coordinates are int16, cell corners at most
    /// `32767 + 32 x 65535`.
    pub fn nearest(&self, q: [i16; 3], limit: u64) -> Option<Neighbour> {
        match self.table.as_ref().and_then(|t| t.list(q)) {
            Some(list) => self.nearest_listed(list, q, limit),
            None => self.nearest_in_grid(q, limit),
        }
    }

    /// The nearest of a table cell's candidates (u16 little-endian indices,
    /// ascending) below `limit`. The list holds every point that can be
    /// the nearest anywhere in the cell, ties included; a tie goes to the
    /// point the grid search would meet first: the one in the nearer grid
    /// shell around `q`'s cell, then the lower index (the list ascends).
    fn nearest_listed(&self, list: &[u8], q: [i16; 3], limit: u64) -> Option<Neighbour> {
        let [x, y, z] = q.map(i32::from);
        // A limit above every listed distance (see `scan_list`) is one no
        // distance reaches either.
        let (index, bound, tied) = scan_list(
            self.cloud.points,
            list,
            [x, y, z],
            limit.min(u32::MAX as u64) as u32,
        );
        let index = if tied {
            self.break_tie(list, q, bound)
        } else {
            index
        };
        (index != usize::MAX).then_some(Neighbour {
            index,
            distance_squared: bound as u64,
        })
    }

    /// Of the listed points at squared distance `d` from `q` (two or
    /// more), the one the grid search would meet first: in the nearest
    /// grid shell around `q`'s cell, then the lowest index.
    #[cold]
    #[inline(never)]
    fn break_tie(&self, list: &[u8], q: [i16; 3], d: u32) -> usize {
        let mut best = (i32::MAX, usize::MAX);
        for entry in list.chunks_exact(2) {
            let i = u16::from_le_bytes([entry[0], entry[1]]) as usize;
            if distance_squared(self.point(i), q) == d as u64 {
                best = best.min((self.shell(i, q), i));
            }
        }
        best.1
    }

    /// The grid shell around `q`'s (clamped) cell that holds point `i`:
    /// the Chebyshev distance of their cells.
    fn shell(&self, i: usize, q: [i16; 3]) -> i32 {
        let p = self.point(i);
        let mut shell = 0;
        for ((&pv, &qv), &origin) in p.iter().zip(&q).zip(&self.cloud.origin) {
            let (a, b) = (
                self.axis_cell(origin as i32, pv as i32),
                self.axis_cell(origin as i32, qv as i32),
            );
            shell = shell.max((a - b).abs());
        }
        shell
    }

    /// [`Self::nearest`] by walking the grid.
    fn nearest_in_grid(&self, q: [i16; 3], limit: u64) -> Option<Neighbour> {
        let ([x, y, z], [ox, oy, oz]) = (q, self.cloud.origin);
        let cell = self.cloud.cell as i32;
        let axis = |origin: i16, v: i16| Axis {
            origin: origin as i32,
            cell,
            v: v as i32,
        };
        let axes = [axis(ox, x), axis(oy, y), axis(oz, z)];
        // A query whose distance to the grid's box (which holds every
        // point) is already at the limit has no point below it: the shells
        // below would find none either, after walking them all.
        let outside: u64 = axes.iter().map(|a| a.outside(self.grid) as u64).sum();
        if outside >= limit {
            return None;
        }
        let centre = axes.map(|a| self.axis_cell(a.origin, a.v));
        let mut best = Best {
            index: usize::MAX,
            bound: limit,
        };
        let g = self.grid;
        for r in 0..g {
            let lo = centre.map(|c| (c - r).max(0));
            let hi = centre.map(|c| (c + r).min(g - 1));
            // The shell's cells (Chebyshev distance `r` from the centre
            // cell) in x, y, z order: every z of the box where x or y is on
            // the shell, else only its two z faces. An x plane, or a z row,
            // whose slabs are already no closer than the best so far is
            // passed over whole: the bound only falls, so the per-cell test
            // below would skip each of its cells anyway.
            for cx in lo[0]..=hi[0] {
                let sx = axes[0].slab(cx) as u64;
                if sx >= best.bound {
                    continue;
                }
                let x_on_shell = (cx - centre[0]).abs() == r;
                for cy in lo[1]..=hi[1] {
                    let sxy = sx + axes[1].slab(cy) as u64;
                    if sxy >= best.bound {
                        continue;
                    }
                    let row = (cx * g + cy) * g;
                    let mut visit = |cz: i32| {
                        // Skip a cell that cannot hold a point closer than
                        // the best so far: its box is at least this far.
                        if sxy + (axes[2].slab(cz) as u64) < best.bound {
                            self.scan_cell((row + cz) as usize, q, &mut best);
                        }
                    };
                    if x_on_shell || (cy - centre[1]).abs() == r {
                        (lo[2]..=hi[2]).for_each(&mut visit);
                    } else {
                        // r >= 1 here: two distinct faces, in z order.
                        if centre[2] - r >= 0 {
                            visit(centre[2] - r);
                        }
                        if centre[2] + r < g {
                            visit(centre[2] + r);
                        }
                    }
                }
            }
            // Distance from q to the nearest face of the visited box that
            // still has cells beyond it: a lower bound for every unvisited
            // point.
            let mut gap = i32::MAX;
            for ((axis, &lo), &hi) in axes.iter().zip(&lo).zip(&hi) {
                if lo > 0 {
                    gap = gap.min(axis.v - axis.corner(lo));
                }
                if hi < g - 1 {
                    gap = gap.min(axis.corner(hi + 1) - axis.v);
                }
            }
            if gap == i32::MAX || (gap > 0 && (gap as u64) * (gap as u64) >= best.bound) {
                break;
            }
        }
        (best.index != usize::MAX).then_some(Neighbour {
            index: best.index,
            distance_squared: best.bound,
        })
    }

    /// Offers cell `c`'s points to the nearest-point search (see
    /// [`Best::scan`]); an empty cell costs no call.
    #[inline(always)]
    fn scan_cell(&self, c: usize, q: [i16; 3], best: &mut Best) {
        let (start, end) = (self.offset(c), self.offset(c + 1));
        // Offsets ascend within the points (checked at load).
        if let Some(points) = self.cloud.points.get(6 * start..6 * end)
            && !points.is_empty()
        {
            best.scan(points, start, q);
        }
    }
}

/// The best point of a search so far (`usize::MAX`: none) and the squared
/// distance a point must beat.
struct Best {
    index: usize,
    bound: u64,
}

impl Best {
    /// Offers the stored points `points` (6 bytes each), the first of
    /// index `first`, to the search: a point strictly nearer than the
    /// bound becomes the best and lowers it. (Not inlined: on its own the
    /// loop keeps the query and the bound in registers instead of spilling
    /// the whole search's state.)
    #[inline(never)]
    fn scan(&mut self, points: &[u8], first: usize, q: [i16; 3]) {
        for (i, p) in (first..).zip(points.chunks_exact(6)) {
            let d = distance_squared(stored_point(p), q);
            if d < self.bound {
                self.bound = d;
                self.index = i;
            }
        }
    }
}

/// The first of the listed points (u16 little-endian indices into
/// `points`, six bytes a point) strictly nearer to `q` than `bound`
/// (squared steps): its index (`usize::MAX` if none), its squared
/// distance (else `bound`), and whether another listed point lies at the
/// same distance (then [`Template::nearest`] breaks the tie).
///
/// Squared distances in u32: every listed point lies within
/// `table::MAX_REACH` steps of `q` along each axis (checked at load), so
/// three squares stay below 2^32 and the wrapping operations never wrap.
/// Not inlined: on its own the loop keeps the query and the bound in
/// registers.
#[inline(never)]
fn scan_list(points: &[u8], list: &[u8], q: [i32; 3], mut bound: u32) -> (usize, u32, bool) {
    let stored = points.as_chunks::<6>().0;
    let probe = Probe::new(q);
    let (mut index, mut tied) = (usize::MAX, false);
    for entry in list.as_chunks::<2>().0 {
        let i = u16::from_le_bytes(*entry) as usize;
        // The loader refuses indices past the end: the zeros are never read.
        let d = probe.distance_squared(stored.get(i).unwrap_or(&[0; 6]));
        if d <= bound {
            // Equal to the limit before any point is found is no tie;
            // the caller sees `index == usize::MAX` then.
            tied = d == bound;
            if !tied {
                (index, bound) = (i, d);
            }
        }
    }
    (index, bound, tied && index != usize::MAX)
}

/// A query of [`scan_list`]: the squared distance to a stored point (six
/// bytes, three int16 little-endian) within `table::MAX_REACH` steps of it
/// along each axis, in u32 (three squares of at most 32,767 stay below
/// 2^32; the wrapping operations never wrap).
#[cfg(not(pcrnet_arm_dsp))]
struct Probe([i32; 3]);

#[cfg(not(pcrnet_arm_dsp))]
impl Probe {
    #[inline(always)]
    fn new(q: [i32; 3]) -> Self {
        Probe(q)
    }

    #[inline(always)]
    fn distance_squared(&self, bytes: &[u8; 6]) -> u32 {
        let [px, py, pz] = stored_point(bytes);
        let q = self.0;
        let (dx, dy, dz) = (
            (px as i32 - q[0]) as u32,
            (py as i32 - q[1]) as u32,
            (pz as i32 - q[2]) as u32,
        );
        dx.wrapping_mul(dx)
            .wrapping_add(dy.wrapping_mul(dy))
            .wrapping_add(dz.wrapping_mul(dz))
    }
}

/// [`Probe`] on the Cortex-M4/M7: x and y of a stored point loaded as one
/// word, both differences by one `SSUB16` (exact: within 32,767 steps) and
/// their squares summed by one `SMUAD` (at most 2 x 32,767^2 < 2^31), z
/// as the portable probe does: the same value, five instructions fewer a
/// candidate (17 instead of 22 in the loop).
#[cfg(pcrnet_arm_dsp)]
struct Probe {
    /// The query's x (low half) and y (high half).
    xy: u32,
    z: i32,
}

#[cfg(pcrnet_arm_dsp)]
impl Probe {
    #[inline(always)]
    fn new(q: [i32; 3]) -> Self {
        Probe {
            xy: (q[0] as u32 & 0xFFFF) | ((q[1] as u32) << 16),
            z: q[2],
        }
    }

    #[inline(always)]
    fn distance_squared(&self, bytes: &[u8; 6]) -> u32 {
        use crate::kernel::dsp::{smuad, ssub16};
        let [a, b, c, d, e, f] = *bytes;
        let xy = ssub16(u32::from_le_bytes([a, b, c, d]), self.xy);
        let dz = (i16::from_le_bytes([e, f]) as i32 - self.z) as u32;
        (smuad(xy, xy) as u32).wrapping_add(dz.wrapping_mul(dz))
    }
}

/// One axis of a search: the grid along it and the query's coordinate.
#[derive(Clone, Copy)]
struct Axis {
    origin: i32,
    cell: i32,
    v: i32,
}

impl Axis {
    /// The low corner of cell `c` along this axis (`c = grid` gives the
    /// grid's far edge).
    #[inline(always)]
    fn corner(self, c: i32) -> i32 {
        self.origin + c * self.cell
    }

    /// The squared distance from the query to the grid's `grid` cells
    /// along this axis (0 inside them), capped at `u32::MAX` as
    /// [`Self::slab`] is.
    #[inline(always)]
    fn outside(self, grid: i32) -> u32 {
        let (lo, hi) = (self.corner(0), self.corner(grid) - 1);
        let d = (lo - self.v).max(self.v - hi).max(0) as u32;
        if d > 0xFFFF { u32::MAX } else { d * d }
    }

    /// The squared distance from the query to the slab of cells `c` along
    /// this axis (0 inside it), capped at `u32::MAX`: a cell's box is at
    /// least the sum of its three slabs' away. (The cap can only make a
    /// cell look nearer than it is, and visiting a cell that holds no
    /// point below the bound changes nothing.)
    #[inline(always)]
    fn slab(self, c: i32) -> u32 {
        let lo = self.corner(c);
        let d = (lo - self.v).max(self.v - (lo + self.cell - 1)).max(0) as u32;
        // Below 2^16 the square fits in u32.
        if d > 0xFFFF { u32::MAX } else { d * d }
    }
}

/// A stored point's six bytes (three int16 little-endian) as int16 steps
/// (zeros if `bytes` is short: callers pass slices of six).
#[inline(always)]
fn stored_point(bytes: &[u8]) -> [i16; 3] {
    match bytes {
        &[a, b, c, d, e, f, ..] => [
            i16::from_le_bytes([a, b]),
            i16::from_le_bytes([c, d]),
            i16::from_le_bytes([e, f]),
        ],
        _ => [0; 3],
    }
}

/// Squared Euclidean distance of two int16-step points (exact: each
/// difference fits in i32, the sum of squares in u64).
#[inline(always)]
pub fn distance_squared(a: [i16; 3], b: [i16; 3]) -> u64 {
    let mut d = 0i64;
    for k in 0..3 {
        let e = (a[k] as i32 - b[k] as i32) as i64;
        d += e * e;
    }
    d as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::SplitMix64;

    fn brute(points: &[[i16; 3]], q: [i16; 3]) -> u64 {
        points
            .iter()
            .map(|&p| distance_squared(p, q))
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
        check(&Template::new(cloud, None).unwrap());
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
                    let q = [0; 3].map(|_: i32| rng.int(-32767, 32767) as i16);
                    let n = t.nearest(q, u64::MAX).unwrap();
                    assert_eq!(n.distance_squared, brute(&points, q));
                    assert_eq!(distance_squared(t.point(n.index), q), n.distance_squared);
                    // With a limit, points at or beyond it are not returned;
                    // just above it the same point is (also from outside
                    // the grid's box, where the search may stop early).
                    assert_eq!(t.nearest(q, n.distance_squared), None);
                    assert_eq!(t.nearest(q, n.distance_squared + 1), Some(n));
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
                let cell = |p: [i16; 3]| {
                    let c = t.cell_of(p).unwrap() as i32;
                    [c / (g * g), c / g % g, c % g]
                };
                let (mut ties, mut shells) = (0, 0);
                for _ in 0..400 {
                    let q =
                        [0; 3].map(|_: i32| (rng.int(-5, 5) * 1500 + rng.int(-1, 1) * 750) as i16);
                    let centre =
                        [0, 1, 2].map(|a| t.axis_cell(t.cloud.origin[a] as i32, q[a] as i32));
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
        assert!(Template::new(cloud.clone(), None).is_ok());
        // A point moved out of its cell.
        let mut moved = [0u8; 18];
        moved.copy_from_slice(cloud.points);
        moved[0..2].copy_from_slice(&30000i16.to_le_bytes());
        let bad = TemplateCloud {
            points: &moved,
            ..cloud.clone()
        };
        assert!(Template::new(bad, None).is_err());
        let bad = TemplateCloud {
            step: f32::NAN,
            ..cloud.clone()
        };
        assert!(Template::new(bad, None).is_err());
        let zero = [0u8; 9];
        let bad = TemplateCloud {
            normals: &zero,
            ..cloud.clone()
        };
        assert!(Template::new(bad, None).is_err());
        let mut turns = heapless::Vec::new();
        let _ = turns.push([2.0, 0.0, 0.0, 0.0]);
        let bad = TemplateCloud { turns, ..cloud };
        assert!(Template::new(bad, None).is_err());
    }

    /// The Cortex-M4/M7 probe's arithmetic (`SSUB16` on the packed x and
    /// y, `SMUAD` of the differences, z apart), modelled in software: the
    /// portable probe's value wherever the loader lets a candidate be
    /// listed (within 32,767 steps of the query along each axis),
    /// including the extremes. The QEMU harness checks the instructions
    /// themselves against the host on every registration.
    #[cfg(not(pcrnet_arm_dsp))]
    #[test]
    fn packed_differences_give_the_portable_distance() {
        let halves = |v: u32| [v as u16, (v >> 16) as u16];
        let ssub16 = |a: u32, b: u32| {
            let ([al, ah], [bl, bh]) = (halves(a), halves(b));
            al.wrapping_sub(bl) as u32 | (ah.wrapping_sub(bh) as u32) << 16
        };
        let smuad = |a: u32, b: u32| {
            let ([al, ah], [bl, bh]) = (halves(a), halves(b));
            (al as i16 as i32 * bl as i16 as i32).wrapping_add(ah as i16 as i32 * bh as i16 as i32)
        };
        let reach = table::MAX_REACH;
        let cases = [
            ([0i16, 0, 0], [0i32, 0, 0]),
            ([i16::MAX, i16::MAX, i16::MAX], [0, 0, 0]),
            ([i16::MIN + 1, i16::MIN + 1, i16::MIN + 1], [0, 0, 0]),
            ([i16::MAX, i16::MIN + 1, 7], [0, 0, 7 - reach]),
            ([-5, 12, -3], [-5 + reach, 12 - reach, -3 + reach]),
            ([100, -200, 300], [-400, 500, -600]),
        ];
        for (p, q) in cases {
            for k in 0..3 {
                assert!((p[k] as i32 - q[k]).abs() <= reach);
            }
            let [x, y, z] = p.map(i16::to_le_bytes);
            let bytes = [x[0], x[1], y[0], y[1], z[0], z[1]];
            let qxy = (q[0] as u32 & 0xFFFF) | ((q[1] as u32) << 16);
            let xy = ssub16(
                u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
                qxy,
            );
            let dz = (i16::from_le_bytes([bytes[4], bytes[5]]) as i32 - q[2]) as u32;
            let packed = (smuad(xy, xy) as u32).wrapping_add(dz.wrapping_mul(dz));
            assert_eq!(
                packed,
                Probe::new(q).distance_squared(&bytes),
                "{p:?} {q:?}"
            );
            let exact: i64 = (0..3).map(|k| (p[k] as i64 - q[k] as i64).pow(2)).sum();
            assert_eq!(packed as i64, exact, "{p:?} {q:?}");
        }
    }
}
