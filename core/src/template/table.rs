//! The template's closest-point table ([`NearestTable`], format 4): for
//! each cell of a box around the template, the few stored points that can
//! be the nearest to some place in the cell. A search there reads its cell's
//! list instead of walking the grid's shells: about 3 to 6 distances
//! instead of a few dozen cells, points and bounds.
//!
//! Building one ([`build_table`]) is the host's work at export; a device
//! only checks it once ([`Table::new`]) and reads it.
//!
//! Exact by construction: a point is left out of a cell's list only when
//! another point is strictly nearer to every place in the cell. For points
//! `a` and `b`, `|q - a|^2 - |q - b|^2 = sum_k (b_k - a_k)(2 q_k - a_k - b_k)`
//! is linear in `q`, so it is positive over a box exactly when it is
//! positive at the box's corners: its minimum is a sum of one choice per
//! axis. Ties are never left out, so a search over the list can break them
//! as the grid search does ([`super::Template::nearest`]).

use super::Template;
use crate::error::{Error, Result};
use crate::format::NearestTable;

/// Most cells a table may have (its offsets then take 256 KB).
pub const MAX_TABLE_CELLS: usize = 1 << 17;

/// The farthest a listed point may lie from any place in its cell, along
/// each axis, in steps: three squares of it sum to less than `2^32`, so a
/// search over a list takes exact squared distances in 32 bits (one
/// `MUL` and two `MLA` on a Cortex-M4 instead of 64-bit `SMLAL`s).
/// [`Table::new`] refuses a table that breaks it; a list's points are
/// near their cell (its nearest ones), far inside this.
pub(super) const MAX_REACH: i32 = i16::MAX as i32;

/// Where a table's cells lie: `dims` cubic cells of `edge` int16 steps per
/// axis from `origin` (x slowest, z fastest).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableShape {
    /// Lowest corner, int16 steps.
    pub origin: [i16; 3],
    /// Edge of a cell, int16 steps.
    pub edge: u16,
    /// Cells along x, y and z.
    pub dims: [u8; 3],
}

impl TableShape {
    /// A box of cells over the template's points: `across` cells over the
    /// widest side of their bounding box (the cell edge rounded up), and
    /// `margin` cells more on every side for queries off the surface
    /// (clipped to the int16 range).
    pub fn around(template: &Template<'_>, across: u8, margin: u8) -> Result<Self> {
        if across == 0 {
            return Err(Error::InvalidParameter {
                what: "closest-point table: at least one cell across the template",
            });
        }
        let (mut lo, mut hi) = ([i32::MAX; 3], [i32::MIN; 3]);
        for i in 0..template.len() {
            for (k, &v) in template.point(i).iter().enumerate() {
                lo[k] = lo[k].min(v as i32);
                hi[k] = hi[k].max(v as i32);
            }
        }
        let extent = (0..3).map(|k| hi[k] - lo[k] + 1).max().unwrap_or(1);
        let edge = ((extent + across as i32 - 1) / across as i32).max(1);
        let too_big = Error::InvalidParameter {
            what: "closest-point table: more than 255 cells along an axis or MAX_TABLE_CELLS in all; fewer cells across or a smaller margin",
        };
        let mut shape = TableShape {
            origin: [0; 3],
            edge: u16::try_from(edge).map_err(|_| too_big)?,
            dims: [0; 3],
        };
        for k in 0..3 {
            let start = (lo[k] - margin as i32 * edge).max(i16::MIN as i32);
            let end = (hi[k] + 1 + margin as i32 * edge).min(i16::MAX as i32 + 1);
            shape.origin[k] = start as i16;
            shape.dims[k] = u8::try_from((end - start + edge - 1) / edge).map_err(|_| too_big)?;
        }
        if shape.cells() > MAX_TABLE_CELLS {
            return Err(too_big);
        }
        Ok(shape)
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// The inclusive int16-step corners of cell `(i, j, k)`.
    /// (Destructured, not indexed: the loader calls it, and no panic path
    /// may be reachable there.)
    fn cell_box(&self, at: [i32; 3]) -> ([i64; 3], [i64; 3]) {
        let ([ox, oy, oz], [x, y, z], e) = (self.origin, at, self.edge as i64);
        let corner = |o: i16, c: i32| o as i64 + c as i64 * e;
        let lo = [corner(ox, x), corner(oy, y), corner(oz, z)];
        (lo, lo.map(|v| v + e - 1))
    }
}

/// Where a point must lie to be within [`MAX_REACH`] steps, along every
/// axis, of every place in the cell of inclusive corners `lo` and `hi`
/// ([`TableShape::cell_box`]): per axis `hi - MAX_REACH ..= lo +
/// MAX_REACH`. Only such points may be listed (see [`Table::new`]).
fn reach_span(([l0, l1, l2], [h0, h1, h2]): ([i64; 3], [i64; 3])) -> [(i32, i32); 3] {
    let reach = MAX_REACH as i64;
    let span = |lo: i64, hi: i64| {
        let clamp = |v: i64| v.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
        (clamp(hi - reach), clamp(lo + reach))
    };
    [span(l0, h0), span(l1, h1), span(l2, h2)]
}

/// Whether `p` lies in a [`reach_span`].
#[inline(always)]
fn within(span: [(i32, i32); 3], p: [i16; 3]) -> bool {
    let inside = |(lo, hi): (i32, i32), v: i16| lo <= v as i32 && v as i32 <= hi;
    inside(span[0], p[0]) && inside(span[1], p[1]) && inside(span[2], p[2])
}

/// `u16` slots of work [`build_table`] and [`table_len`] need for a
/// template of `points` points.
pub const fn table_work_len(points: usize) -> usize {
    2 * points
}

/// Bytes of a table of `shape` for `template`, cells whose list would be
/// longer than `max_list` left out: `(offset bytes, candidate bytes)`.
pub fn table_len(
    template: &Template<'_>,
    shape: &TableShape,
    max_list: usize,
    work: &mut [u16],
) -> Result<(usize, usize)> {
    let mut entries = 0usize;
    for_each_list(template, shape, max_list, work, |_, list| {
        entries += list.len();
    })?;
    Ok((2 * (shape.cells() + 1), 2 * entries))
}

/// Builds the closest-point table of `shape` for `template` into
/// `offsets` and `candidates` (sizes from [`table_len`]; `work` holds
/// [`table_work_len`] slots). A cell whose list would be longer than
/// `max_list`, or name a point more than 32,767 steps (the int16 range)
/// from some place in it along an axis, gets none: the grid search answers there. Deterministic; no
/// allocation. Errors when a buffer is short or the table would hold more
/// than 65,535 entries.
pub fn build_table<'o>(
    template: &Template<'_>,
    shape: &TableShape,
    max_list: usize,
    work: &mut [u16],
    offsets: &'o mut [u8],
    candidates: &'o mut [u8],
) -> Result<NearestTable<'o>> {
    let (no, nc) = table_len(template, shape, max_list, work)?;
    if nc / 2 > u16::MAX as usize {
        return Err(Error::InvalidParameter {
            what: "closest-point table: more than 65535 entries; fewer cells or a shorter max list",
        });
    }
    for (needed, available) in [(no, offsets.len()), (nc, candidates.len())] {
        if available < needed {
            return Err(Error::BufferTooSmall { needed, available });
        }
    }
    let (offsets, candidates) = (&mut offsets[..no], &mut candidates[..nc]);
    offsets[..2].copy_from_slice(&0u16.to_le_bytes());
    let mut at = 0usize;
    for_each_list(template, shape, max_list, work, |cell, list| {
        for &i in list {
            candidates[2 * at..2 * at + 2].copy_from_slice(&i.to_le_bytes());
            at += 1;
        }
        offsets[2 * cell + 2..2 * cell + 4].copy_from_slice(&(at as u16).to_le_bytes());
    })?;
    Ok(NearestTable {
        origin: shape.origin,
        edge: shape.edge,
        dims: shape.dims,
        offsets,
        candidates,
    })
}

/// Calls `each(cell, list)` for every cell in order with its list of
/// candidates (ascending; empty when longer than `max_list`).
fn for_each_list(
    template: &Template<'_>,
    shape: &TableShape,
    max_list: usize,
    work: &mut [u16],
    mut each: impl FnMut(usize, &[u16]),
) -> Result<()> {
    let n = template.len();
    let needed = table_work_len(n);
    let available = work.len();
    if available < needed {
        return Err(Error::BufferTooSmall { needed, available });
    }
    let (near, kept) = work.split_at_mut(n);
    let points = |i: u16| template.point(i as usize).map(i64::from);
    let dims = shape.dims.map(i32::from);
    let mut cell = 0usize;
    for i in 0..dims[0] {
        for j in 0..dims[1] {
            for k in 0..dims[2] {
                let (lo, hi) = shape.cell_box([i, j, k]);
                let farthest = |p: [i64; 3]| -> i64 {
                    (0..3)
                        .map(|a| (p[a] - lo[a]).abs().max((hi[a] - p[a]).abs()).pow(2))
                        .sum()
                };
                let closest = |p: [i64; 3]| -> i64 {
                    (0..3)
                        .map(|a| (lo[a] - p[a]).max(p[a] - hi[a]).max(0).pow(2))
                        .sum()
                };
                // Every place in the cell is within `reach` of point `centre`.
                let (mut reach, mut centre) = (i64::MAX, 0u16);
                for i in 0..n as u16 {
                    let f = farthest(points(i));
                    if f < reach {
                        (reach, centre) = (f, i);
                    }
                }
                let mut count = 0;
                for i in 0..n as u16 {
                    if closest(points(i)) <= reach {
                        near[count] = i;
                        count += 1;
                    }
                }
                let near = &near[..count];
                let mut len = 0;
                // Whether `b` is strictly nearer than `a` everywhere in the
                // cell: min over the cell of |q - a|^2 - |q - b|^2 > 0.
                let beats = |b: u16, a: u16| {
                    let (pa, pb) = (points(a), points(b));
                    (0..3)
                        .map(|x| {
                            let d = pb[x] - pa[x];
                            (d * (2 * lo[x] - pa[x] - pb[x])).min(d * (2 * hi[x] - pa[x] - pb[x]))
                        })
                        .sum::<i64>()
                        > 0
                };
                for &a in near {
                    // The most central point beats most; then all of them.
                    let dominated = beats(centre, a) || near.iter().any(|&b| beats(b, a));
                    if !dominated {
                        // Too long a list, or a point too far for the
                        // search's 32-bit distances: the grid answers here.
                        if len == max_list
                            || !within(reach_span((lo, hi)), template.point(a as usize))
                        {
                            len = 0;
                            break;
                        }
                        kept[len] = a;
                        len += 1;
                    }
                }
                each(cell, &kept[..len]);
                cell += 1;
            }
        }
    }
    Ok(())
}

/// A checked [`NearestTable`].
#[derive(Debug, Clone, Copy)]
pub(super) struct Table<'a> {
    origin: [i32; 3],
    edge: u32,
    dims: [u32; 3],
    offsets: &'a [u8],
    candidates: &'a [u8],
}

impl<'a> Table<'a> {
    /// Checks a table against a template's stored points (six bytes each,
    /// as in the blob): a box of at most [`MAX_TABLE_CELLS`] cells, offsets
    /// that start at 0 and ascend to the entry count, entries that name
    /// stored points in ascending order within each cell, each point within
    /// [`MAX_REACH`] steps along every axis of every place in its cell (so
    /// a search over a list may take squared distances in 32 bits). (That
    /// each list holds its cell's nearest points is the builder's promise,
    /// as the grid's cells are.)
    pub(super) fn new(t: NearestTable<'a>, stored: &[u8]) -> Result<Self> {
        let points = stored.len() / 6;
        let bad = |what| Err(Error::InconsistentDimensions { what });
        let cells: usize = t.dims.iter().map(|&d| d as usize).product();
        if cells == 0 || cells > MAX_TABLE_CELLS || t.edge == 0 {
            return bad("closest-point table size");
        }
        if t.offsets.len() != 2 * (cells + 1) || !t.candidates.len().is_multiple_of(2) {
            return bad("closest-point table offsets");
        }
        let table = Table {
            origin: t.origin.map(i32::from),
            edge: t.edge as u32,
            dims: t.dims.map(u32::from),
            offsets: t.offsets,
            candidates: t.candidates,
        };
        let mut start = 0usize;
        if table.offset(0) != 0 {
            return bad("closest-point table offsets");
        }
        let shape = TableShape {
            origin: t.origin,
            edge: t.edge,
            dims: t.dims,
        };
        let [nx, ny, nz] = t.dims.map(i32::from);
        let mut c = 0;
        for x in 0..nx {
            for y in 0..ny {
                for z in 0..nz {
                    let span = reach_span(shape.cell_box([x, y, z]));
                    let end = table.offset(c + 1);
                    if end < start || 2 * end > t.candidates.len() {
                        return bad("closest-point table offsets");
                    }
                    let mut last = None;
                    for e in t.candidates[2 * start..2 * end].chunks_exact(2) {
                        let i = u16::from_le_bytes([e[0], e[1]]) as usize;
                        if i >= points || last.is_some_and(|l| l >= i) {
                            return bad("closest-point table entries");
                        }
                        let p = stored
                            .get(6 * i..6 * i + 6)
                            .map_or([0; 3], super::stored_point);
                        if !within(span, p) {
                            return bad("closest-point table entry too far from its cell");
                        }
                        last = Some(i);
                    }
                    start = end;
                    c += 1;
                }
            }
        }
        if 2 * start != t.candidates.len() {
            return bad("closest-point table offsets");
        }
        Ok(table)
    }

    /// Entry `c` of the offsets (0 past the end).
    fn offset(&self, c: usize) -> usize {
        match self.offsets.get(2 * c..2 * c + 2) {
            Some(&[a, b]) => u16::from_le_bytes([a, b]) as usize,
            _ => 0,
        }
    }

    /// The list (u16 little-endian point indices) of the cell holding `q`;
    /// `None` outside the box or in a cell that is not tabulated.
    #[inline(always)]
    pub(super) fn list(&self, q: [i16; 3]) -> Option<&'a [u8]> {
        let mut index = 0usize;
        for ((&v, &origin), &dim) in q.iter().zip(&self.origin).zip(&self.dims) {
            let rel = u32::try_from(v as i32 - origin).ok()?;
            let c = rel.checked_div(self.edge)?;
            if c >= dim {
                return None;
            }
            index = index * dim as usize + c as usize;
        }
        let (start, end) = (self.offset(index), self.offset(index + 1));
        self.candidates
            .get(2 * start..2 * end)
            .filter(|list| !list.is_empty())
    }

    /// The table as stored.
    pub(super) fn stored(&self) -> NearestTable<'a> {
        NearestTable {
            origin: self.origin.map(|v| v as i16),
            edge: self.edge as u16,
            dims: self.dims.map(|v| v as u8),
            offsets: self.offsets,
            candidates: self.candidates,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{BuildOut, build, build_len};
    use super::*;
    use crate::testing::SplitMix64;
    use std::vec;
    use std::vec::Vec;

    /// Runs `check` on `points` laid out on a `grid`-cell grid, with and
    /// without a closest-point table of `across` cells and `margin`.
    fn with_tables(
        points: &[[i16; 3]],
        grid: u8,
        across: u8,
        margin: u8,
        max_list: usize,
        check: impl FnOnce(&Template<'_>, &Template<'_>),
    ) {
        let (np, nn, nc) = build_len(points.len(), grid);
        let (mut pb, mut nb, mut cb) = (vec![0u8; np], vec![0u8; nn], vec![0u8; nc]);
        let normals = vec![[127i8, 0, 0]; points.len()];
        let out = BuildOut {
            points: &mut pb,
            normals: &mut nb,
            cells: &mut cb,
        };
        let cloud = build(points, &normals, 1e-4, grid, &[], out).unwrap();
        let plain = Template::new(cloud.clone(), None).unwrap();
        let shape = TableShape::around(&plain, across, margin).unwrap();
        let mut work = vec![0u16; table_work_len(points.len())];
        let (no, nc) = table_len(&plain, &shape, max_list, &mut work).unwrap();
        let (mut ob, mut cb) = (vec![0u8; no], vec![0u8; nc]);
        let table = build_table(&plain, &shape, max_list, &mut work, &mut ob, &mut cb).unwrap();
        let tabled = Template::new(cloud, Some(table)).unwrap();
        assert_eq!(tabled.table(), Some(table));
        check(&plain, &tabled);
    }

    /// The table finds the grid search's point, distance and index, on
    /// random points and queries in and around the box, with limits.
    #[test]
    fn table_finds_the_grid_search_point() {
        let mut rng = SplitMix64(11);
        for (grid, across, margin) in [(1u8, 4u8, 0u8), (4, 8, 2), (6, 16, 3), (8, 12, 1)] {
            let points: Vec<[i16; 3]> = (0..200)
                .map(|_| [0; 3].map(|_: i32| rng.int(-6000, 6000) as i16))
                .collect();
            with_tables(&points, grid, across, margin, 32, |plain, tabled| {
                let mut listed = 0;
                for _ in 0..3000 {
                    let q = [0; 3].map(|_: i32| rng.int(-9000, 9000) as i16);
                    let limit = if rng.int(0, 3) == 0 {
                        rng.int(0, 4_000_000) as u64
                    } else {
                        u64::MAX
                    };
                    assert_eq!(tabled.nearest(q, limit), plain.nearest(q, limit), "{q:?}");
                    listed += usize::from(tabled.table.and_then(|t| t.list(q)).is_some());
                }
                assert!(
                    listed > 500,
                    "grid {grid}: {listed} of 3000 queries in the table"
                );
            });
        }
    }

    /// Points and queries on a coarse lattice tie often, also across grid
    /// shells: the table breaks them as the grid search does.
    #[test]
    fn table_breaks_ties_as_the_grid_search() {
        let mut rng = SplitMix64(13);
        for grid in [2u8, 3, 5] {
            let points: Vec<[i16; 3]> = (0..150)
                .map(|_| [0; 3].map(|_: i32| (rng.int(-4, 4) * 1500) as i16))
                .collect();
            with_tables(&points, grid, 9, 1, 64, |plain, tabled| {
                let mut ties = 0;
                for _ in 0..2000 {
                    let q =
                        [0; 3].map(|_: i32| (rng.int(-5, 5) * 1500 + rng.int(-1, 1) * 750) as i16);
                    let want = plain.nearest(q, u64::MAX).unwrap();
                    assert_eq!(tabled.nearest(q, u64::MAX), Some(want), "{q:?}");
                    let tied = (0..plain.len())
                        .filter(|&i| {
                            super::super::distance_squared(plain.point(i), q)
                                == want.distance_squared
                        })
                        .count();
                    ties += usize::from(tied > 1);
                }
                assert!(ties > 200, "grid {grid}: {ties} ties");
            });
        }
    }

    /// A short `max_list` leaves cells out; the search falls back there.
    #[test]
    fn cells_left_out_fall_back_to_the_grid() {
        let mut rng = SplitMix64(17);
        let points: Vec<[i16; 3]> = (0..120)
            .map(|_| [0; 3].map(|_: i32| rng.int(-3000, 3000) as i16))
            .collect();
        with_tables(&points, 4, 6, 2, 2, |plain, tabled| {
            let table = tabled.table.unwrap();
            let empty = (0..216usize.min(table.stored().offsets.len() / 2 - 1))
                .filter(|&c| table.offset(c) == table.offset(c + 1))
                .count();
            assert!(empty > 0, "no cell left out");
            for _ in 0..2000 {
                let q = [0; 3].map(|_: i32| rng.int(-6000, 6000) as i16);
                assert_eq!(tabled.nearest(q, u64::MAX), plain.nearest(q, u64::MAX));
            }
        });
    }

    /// Points over the whole int16 range: the lists keep to points within
    /// `MAX_REACH` of their cell (cells that would need a farther one are
    /// left to the grid), the table is accepted, and the search's 32-bit
    /// distances match the grid search's everywhere, up to the largest.
    #[test]
    fn wide_templates_keep_lists_within_reach() {
        let mut rng = SplitMix64(19);
        let mut points: Vec<[i16; 3]> = (0..60)
            .map(|_| [0; 3].map(|_: i32| rng.int(-32000, -30000) as i16))
            .collect();
        points.extend((0..60).map(|_| [0; 3].map(|_: i32| rng.int(30000, 32000) as i16)));
        with_tables(&points, 4, 12, 0, 64, |plain, tabled| {
            let (mut listed, mut far) = (0, 0u64);
            for _ in 0..4000 {
                let q = [0; 3].map(|_: i32| rng.int(-32767, 32767) as i16);
                let want = plain.nearest(q, u64::MAX);
                assert_eq!(tabled.nearest(q, u64::MAX), want, "{q:?}");
                if tabled.table.and_then(|t| t.list(q)).is_some() {
                    listed += 1;
                    far = far.max(want.map_or(0, |n| n.distance_squared));
                }
            }
            assert!(listed > 500, "{listed} of 4000 queries in the table");
            assert!(far > 1 << 31, "largest listed distance {far}");
            let table = tabled.table().unwrap();
            let empty = (0..table.offsets.len() / 2 - 1)
                .filter(|&c| tabled.table.unwrap().offset(c) == tabled.table.unwrap().offset(c + 1))
                .count();
            assert!(empty > 0, "no cell left to the grid");
        });
    }

    /// Tables that do not fit their template are refused at load.
    #[test]
    fn rejects_inconsistent_tables() {
        let points = [[0i16, 0, 0], [100, 100, 100], [-50, 20, 7]];
        with_tables(&points, 2, 2, 0, 8, |plain, tabled| {
            let good = tabled.table().unwrap();
            let cloud = plain.cloud().clone();
            assert!(Template::new(cloud.clone(), Some(good)).is_ok());
            let refused = |t: NearestTable<'_>| Template::new(cloud.clone(), Some(t)).is_err();
            // An entry naming a point the template does not have.
            let mut entries = good.candidates.to_vec();
            entries[0..2].copy_from_slice(&7u16.to_le_bytes());
            assert!(refused(NearestTable {
                candidates: &entries,
                ..good
            }));
            // One cell listing point 0 (at the origin): accepted where the
            // point is within `MAX_REACH` of the whole cell, refused where
            // the cell starts 32768 steps from it.
            let (offsets, entries) = ([0u8, 0, 1, 0], [0u8, 0]);
            let one = |origin| NearestTable {
                origin,
                edge: 200,
                dims: [1, 1, 1],
                offsets: &offsets,
                candidates: &entries,
            };
            assert!(!refused(one([-100, -100, -100])));
            assert!(refused(one([-32768, -100, -100])));
            // Offsets past the entries, or of the wrong count.
            let mut offsets = good.offsets.to_vec();
            let last = offsets.len() - 2;
            offsets[last..].copy_from_slice(&999u16.to_le_bytes());
            assert!(refused(NearestTable {
                offsets: &offsets,
                ..good
            }));
            assert!(refused(NearestTable {
                offsets: &good.offsets[2..],
                ..good
            }));
            // No cells, a zero edge, a cell list out of order.
            assert!(refused(NearestTable {
                dims: [0, 2, 2],
                ..good
            }));
            assert!(refused(NearestTable { edge: 0, ..good }));
            let (a, b) = (table_list(&good, 0), good.candidates.to_vec());
            if a.len() >= 2 {
                let mut swapped = b.clone();
                swapped.swap(0, 2);
                swapped.swap(1, 3);
                assert!(refused(NearestTable {
                    candidates: &swapped,
                    ..good
                }));
            }
        });
    }

    fn table_list(t: &NearestTable<'_>, c: usize) -> Vec<u16> {
        let at = |c: usize| u16::from_le_bytes([t.offsets[2 * c], t.offsets[2 * c + 1]]) as usize;
        t.candidates[2 * at(c)..2 * at(c + 1)]
            .chunks_exact(2)
            .map(|e| u16::from_le_bytes([e[0], e[1]]))
            .collect()
    }
}
