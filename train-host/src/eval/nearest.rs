//! Exact nearest-neighbour search for host ICP: a uniform grid over the
//! template, searched in the query's cell and its 26 neighbours, with
//! `kiddo`'s k-d tree for the queries the grid cannot settle.
//!
//! ICP spends most of its time here, and most of its queries land close
//! to the template (every iteration after the first few), near where the
//! same source point's match was in the previous iteration. A query with
//! such a hint starts from the hinted point's distance, scans its own
//! cell, and skips every neighbouring cell whose box is already farther
//! than the best point found; a k-d tree would walk from its root and
//! backtrack. Queries outside the grid, or whose nearest point may lie
//! beyond the 3 x 3 x 3 block of cells (far from the template: the first
//! iterations), go to the tree.
//!
//! Both paths are exact: the grid answers only once the best distance is
//! no larger than the distance from the query to the outside of the
//! block, so the nearest distance is always the true one (a different
//! point can be returned only when two template points are exactly
//! equally near).

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// Most cells along one axis.
const MAX_CELLS_PER_AXIS: f64 = 64.0;

/// Empty cells around the template's box on every side: noisy queries
/// just outside the box still have a full block of cells around them.
const PAD: i64 = 2;

/// The nearest template point of a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    /// Its index in the template as given.
    pub index: usize,
    /// Squared distance to it.
    pub squared: f64,
}

/// Exact nearest-neighbour search over a fixed, non-empty template.
pub struct NearestSearch {
    points: Vec<[f64; 3]>,
    tree: ImmutableKdTree<f64, 3>,
    /// Lower corner of the grid's box.
    origin: [f64; 3],
    /// Cell edge length.
    cell: f64,
    /// Cells per axis.
    dims: [i64; 3],
    /// `start[c]..start[c + 1]`: cell `c`'s slots in `sorted`.
    start: Vec<u32>,
    /// The template's points sorted by cell, with their indices.
    sorted: Vec<([f64; 3], u32)>,
    /// The 27 cells of a block: offsets per axis and in the flat layout,
    /// the query's own cell first.
    block: [([i8; 3], isize); 27],
}

impl NearestSearch {
    /// Builds the grid and the tree. `points` must be non-empty and finite
    /// (ICP checks both first).
    pub fn new(points: Vec<[f64; 3]>) -> Self {
        let tree = ImmutableKdTree::new_from_slice(&points);
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        // The box's diagonal over 1.4 x the cube root of the point count:
        // a few template points per occupied cell on a surface (the
        // fastest of 1.0, 1.4 and 2.0 on `ort-bench`'s ICP pairs, within 7%).
        let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let n = points.len() as f64;
        let longest = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        let cell = (diagonal / (1.4 * n.cbrt()))
            .max(longest / MAX_CELLS_PER_AXIS)
            .max(1e-9);
        let origin = lo.map(|v| v - PAD as f64 * cell);
        let dims: [i64; 3] =
            std::array::from_fn(|k| ((hi[k] - origin[k]) / cell).floor() as i64 + 1 + PAD);
        let cells = (dims[0] * dims[1] * dims[2]) as usize;
        let mut block = [([0i8; 3], 0isize); 27];
        let mut j = 1;
        for dz in -1i8..=1 {
            for dy in -1i8..=1 {
                for dx in -1i8..=1 {
                    let flat = (dz as i64 * dims[1] + dy as i64) * dims[0] + dx as i64;
                    if (dx, dy, dz) == (0, 0, 0) {
                        block[0] = ([0; 3], 0);
                    } else {
                        block[j] = ([dx, dy, dz], flat as isize);
                        j += 1;
                    }
                }
            }
        }
        let mut search = NearestSearch {
            points,
            tree,
            origin,
            cell,
            dims,
            start: vec![0; cells + 1],
            sorted: Vec::new(),
            block,
        };
        let ids: Vec<usize> = search
            .points
            .iter()
            .map(|p| search.flat(search.cell_of(p)))
            .collect();
        for &c in &ids {
            search.start[c + 1] += 1;
        }
        for c in 0..cells {
            search.start[c + 1] += search.start[c];
        }
        let mut next = search.start.clone();
        search.sorted = vec![([0.0; 3], 0); ids.len()];
        for (i, &c) in ids.iter().enumerate() {
            search.sorted[next[c] as usize] = (search.points[i], i as u32);
            next[c] += 1;
        }
        search
    }

    /// The template point `index`.
    pub fn point(&self, index: usize) -> [f64; 3] {
        self.points[index]
    }

    fn cell_of(&self, p: &[f64; 3]) -> [i64; 3] {
        std::array::from_fn(|k| ((p[k] - self.origin[k]) / self.cell).floor() as i64)
    }

    fn flat(&self, c: [i64; 3]) -> usize {
        ((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]) as usize
    }

    /// The nearest template point of `q`. `hint`, a template index (for
    /// ICP: the same source point's match in the previous iteration),
    /// only speeds the search up: the answer is the same without it.
    pub fn nearest(&self, q: &[f64; 3], hint: Option<usize>) -> Nearest {
        let c = self.cell_of(q);
        if (0..3).all(|k| (1..self.dims[k] - 1).contains(&c[k]))
            && let Some(found) = self.block_nearest(q, c, hint)
        {
            return found;
        }
        let nn = self.tree.nearest_one::<SquaredEuclidean>(q);
        Nearest {
            index: nn.item as usize,
            squared: nn.distance,
        }
    }

    /// The search in the 3 x 3 x 3 cells around `c` (which holds `q`, not
    /// on the grid's edge): `None` when a nearer point may lie outside.
    fn block_nearest(&self, q: &[f64; 3], c: [i64; 3], hint: Option<usize>) -> Option<Nearest> {
        let mut best = match hint.and_then(|i| self.points.get(i).map(|p| (i, p))) {
            Some((index, p)) => Nearest {
                index,
                squared: squared(p, q),
            },
            None => Nearest {
                index: usize::MAX,
                squared: f64::INFINITY,
            },
        };
        // Squared distances from q to its cell's lower and upper faces.
        let mut below = [0.0; 3];
        let mut above = [0.0; 3];
        let mut margin = f64::INFINITY;
        for k in 0..3 {
            let lo = q[k] - (self.origin[k] + c[k] as f64 * self.cell);
            let hi = self.origin[k] + (c[k] + 1) as f64 * self.cell - q[k];
            below[k] = lo * lo;
            above[k] = hi * hi;
            margin = margin.min(lo.min(hi) + self.cell);
        }
        let own = self.flat(c) as isize;
        for &(d, offset) in &self.block {
            let gap: f64 = (0..3)
                .map(|k| match d[k] {
                    -1 => below[k],
                    1 => above[k],
                    _ => 0.0,
                })
                .sum();
            if gap <= best.squared {
                self.scan((own + offset) as usize, q, &mut best);
            }
        }
        // Every point outside the block is at least `margin` from q
        // (shrunk by a few ulps: a point's cell comes from a rounded division).
        let margin = margin - 1e-12 * (self.cell + margin);
        (best.index != usize::MAX && best.squared <= margin * margin).then_some(best)
    }

    fn scan(&self, cell: usize, q: &[f64; 3], best: &mut Nearest) {
        let (a, b) = (self.start[cell] as usize, self.start[cell + 1] as usize);
        for (p, i) in &self.sorted[a..b] {
            let d = squared(p, q);
            let i = *i as usize;
            if d < best.squared || (d == best.squared && i < best.index) {
                *best = Nearest {
                    index: i,
                    squared: d,
                };
            }
        }
    }
}

fn squared(p: &[f64; 3], q: &[f64; 3]) -> f64 {
    (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::shapes::{Shape, sample};

    fn brute(points: &[[f64; 3]], q: &[f64; 3]) -> f64 {
        points
            .iter()
            .map(|p| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>())
            .fold(f64::INFINITY, f64::min)
    }

    /// Near and far queries, inside and outside the grid, give the exact
    /// nearest distance, and the point returned is at that distance.
    #[test]
    fn exact_against_brute_force() {
        for (shape, n) in [(Shape::Torus, 1024), (Shape::Ell, 300), (Shape::Box, 64)] {
            let points: Vec<[f64; 3]> = sample(shape, n, 3)
                .iter()
                .map(|p| p.map(f64::from))
                .collect();
            let search = NearestSearch::new(points.clone());
            let near = sample(shape, 1000, 9);
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let mut settled = [0usize; 3];
            for j in 0..3000 {
                // On the surface (another sampling of it), inside the box,
                // and far outside it.
                let q: [f64; 3] = match j % 3 {
                    0 => near[j / 3 % near.len()]
                        .map(|v| f64::from(v) + rng.random_range(-0.02..0.02)),
                    1 => std::array::from_fn(|_| rng.random_range(-0.6..0.6)),
                    _ => std::array::from_fn(|_| rng.random_range(-4.0..4.0)),
                };
                let found = search.nearest(&q, None);
                // Any hint gives the same distance.
                let hinted = search.nearest(&q, Some(j % n));
                assert_eq!(hinted.squared, found.squared);
                let d = brute(&points, &q);
                assert_eq!(found.squared, d, "{shape:?} query {q:?}");
                let p = search.point(found.index);
                let e = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>();
                assert_eq!(e, d);
                // The grid alone, where it settles the query, is exact too.
                let c = search.cell_of(&q);
                if (0..3).all(|k| (1..search.dims[k] - 1).contains(&c[k]))
                    && let Some(g) = search.block_nearest(&q, c, None)
                {
                    assert_eq!(g.squared, d, "{shape:?} query {q:?} (grid)");
                    settled[j % 3] += 1;
                }
            }
            // Near the surface the grid answers almost every query itself.
            assert!(
                settled[0] > 900,
                "{shape:?}: grid settled {settled:?} of 1000 each"
            );
        }
    }

    /// A single point, and all points in one place (a zero-size box).
    #[test]
    fn degenerate_templates() {
        let one = NearestSearch::new(vec![[1.0, 2.0, 3.0]]);
        assert_eq!(one.nearest(&[0.0, 0.0, 0.0], None).index, 0);
        let same = NearestSearch::new(vec![[0.5; 3]; 5]);
        let n = same.nearest(&[0.5, 0.5, 0.6], Some(3));
        assert!((n.squared - 0.01).abs() < 1e-12);
    }
}
