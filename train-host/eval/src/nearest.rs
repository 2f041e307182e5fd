//! Exact nearest-neighbour search for host ICP: a uniform grid over the
//! template, searched in the query's cell and its 26 neighbours, with
//! `kiddo`'s k-d tree for the queries the grid cannot settle, and a
//! [`Track`] per moving query point that skips the search altogether
//! while the point provably keeps its nearest template point.
//!
//! ICP spends most of its time here, and most of its queries land close
//! to the template (every iteration after the first few), near where the
//! same source point's match was in the previous iteration. A query
//! starts from that match's distance, scans its own cell, and skips every
//! neighbouring cell whose box is already farther than the best point
//! found; a k-d tree would walk from its root and backtrack. Queries
//! outside the grid, or whose nearest point may lie beyond the 3 x 3 x 3
//! block of cells (far from the template: the first iterations), go to
//! the tree.
//!
//! Once ICP nears convergence its points barely move. A grid search also
//! yields a lower bound `clear` on the distance from the query to every
//! template point other than the one it found (at distance `radius`). By
//! the triangle inequality, after the point has moved a total distance
//! `drift`, its old match is at most `radius + drift` away and every
//! other point at least `clear - drift`; while `radius + 2 drift < clear`
//! (with a margin for rounding) the match stands, and only its distance
//! is computed. (Nüchter et al., "Cached k-d tree search for ICP
//! algorithms", 3DIM 2007, also reuse the previous iteration's search,
//! by starting it from the previous leaf; here a bound decides whether
//! to search at all.)
//!
//! Every path is exact: the grid answers only once the best distance is
//! no larger than the distance from the query to the outside of the
//! block, and a kept match is the unique nearest point, so the nearest
//! distance is always the true one (a different point can be returned
//! only when two template points are exactly equally near).

use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;

/// The tree for far queries: leaves of 16 points (kiddo's default is 32;
/// 16 took 0.87x its time on `ort-bench`'s ICP pairs, 8 0.89x), items as
/// `u32` like the grid's indices.
type Tree = ImmutableKdTree<f64, u32, 3, 16>;

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

/// What the last search for one moving query point found, so that the
/// next can be skipped while its answer provably stands (see the module
/// docs). Start each point with [`Track::default`] and report every move
/// with [`Track::moved`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track {
    /// The template index found (`usize::MAX`: none yet).
    index: usize,
    /// Its distance from the query then.
    radius: f64,
    /// A lower bound on the distance from the query then to every other
    /// template point (0: none known).
    clear: f64,
    /// How far the point has moved since (the sum of its steps).
    drift: f64,
}

impl Default for Track {
    fn default() -> Self {
        Track {
            index: usize::MAX,
            radius: 0.0,
            clear: 0.0,
            drift: 0.0,
        }
    }
}

impl Track {
    /// Records that the query point moved by `step` (a Euclidean length).
    pub fn moved(&mut self, step: f64) {
        self.drift += step;
    }
}

/// Exact nearest-neighbour search over a fixed, non-empty template.
pub struct NearestSearch {
    points: Vec<[f64; 3]>,
    tree: Tree,
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
        let tree = Tree::new_from_slice(&points);
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

    /// The nearest template point of `q`, the current position of the
    /// point `track` follows (for ICP: one source point). The track only
    /// speeds the search up: the answer is the same with a fresh one.
    pub fn nearest(&self, q: &[f64; 3], track: &mut Track) -> Nearest {
        if let Some(&p) = self.points.get(track.index) {
            // Keep the match while it provably stands; the margin covers
            // the rounding of the distances and steps (all near 1 ulp of
            // the cell size or less).
            let slack = 1e-9 * (self.cell + track.clear);
            if track.radius + 2.0 * track.drift + slack < track.clear {
                return Nearest {
                    index: track.index,
                    squared: squared(&p, q),
                };
            }
        }
        let hint = (track.index != usize::MAX).then_some(track.index);
        let c = self.cell_of(q);
        let (found, clear) = if (0..3).all(|k| (1..self.dims[k] - 1).contains(&c[k]))
            && let Some(found) = self.block_nearest(q, c, hint)
        {
            found
        } else {
            let nn = self.tree.nearest_one::<SquaredEuclidean>(q);
            let found = Nearest {
                index: nn.item as usize,
                squared: nn.distance,
            };
            (found, 0.0)
        };
        *track = Track {
            index: found.index,
            radius: found.squared.sqrt(),
            clear,
            drift: 0.0,
        };
        found
    }

    /// The search in the 3 x 3 x 3 cells around `c` (which holds `q`, not
    /// on the grid's edge), starting from the template point `hint`:
    /// `None` when a nearer point may lie outside. With the answer, a
    /// lower bound on the distance from `q` to every other template point.
    fn block_nearest(
        &self,
        q: &[f64; 3],
        c: [i64; 3],
        hint: Option<usize>,
    ) -> Option<(Nearest, f64)> {
        let mut best = Near {
            first: Nearest {
                index: usize::MAX,
                squared: f64::INFINITY,
            },
            second: f64::INFINITY,
        };
        if let Some((index, p)) = hint.and_then(|i| self.points.get(i).map(|p| (i, p))) {
            best.first = Nearest {
                index,
                squared: squared(p, q),
            };
        }
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
        // Every point outside the block is at least `margin` from q
        // (shrunk by a few ulps: a point's cell comes from a rounded division).
        let margin = margin - 1e-12 * (self.cell + margin);
        // The nearest any skipped cell's box comes to q.
        let mut skipped = margin * margin;
        let own = self.flat(c) as isize;
        for &(d, offset) in &self.block {
            let gap: f64 = (0..3)
                .map(|k| match d[k] {
                    -1 => below[k],
                    1 => above[k],
                    _ => 0.0,
                })
                .sum();
            if gap <= best.first.squared {
                self.scan((own + offset) as usize, q, &mut best);
            } else {
                skipped = skipped.min(gap);
            }
        }
        let found = best.first;
        (found.index != usize::MAX && found.squared <= margin * margin)
            .then(|| (found, best.second.min(skipped).sqrt()))
    }

    fn scan(&self, cell: usize, q: &[f64; 3], best: &mut Near) {
        let (a, b) = (self.start[cell] as usize, self.start[cell + 1] as usize);
        for (p, i) in &self.sorted[a..b] {
            let i = *i as usize;
            if i == best.first.index {
                continue;
            }
            let d = squared(p, q);
            if d < best.first.squared || (d == best.first.squared && i < best.first.index) {
                best.second = best.second.min(best.first.squared);
                best.first = Nearest {
                    index: i,
                    squared: d,
                };
            } else {
                best.second = best.second.min(d);
            }
        }
    }
}

/// The best point scanned so far, and the squared distance of the next
/// best (any other point scanned).
struct Near {
    first: Nearest,
    second: f64,
}

fn squared(p: &[f64; 3], q: &[f64; 3]) -> f64 {
    (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use pcrnet_train::shapes::{Shape, sample};

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
                let found = search.nearest(&q, &mut Track::default());
                // A track that found another point gives the same distance.
                let mut other = Track::default();
                search.nearest(&search.point(j % n), &mut other);
                other.moved(squared(&search.point(j % n), &q).sqrt());
                let hinted = search.nearest(&q, &mut other);
                assert_eq!(hinted.squared, found.squared);
                let d = brute(&points, &q);
                assert_eq!(found.squared, d, "{shape:?} query {q:?}");
                let p = search.point(found.index);
                let e = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>();
                assert_eq!(e, d);
                // The grid alone, where it settles the query, is exact too.
                let c = search.cell_of(&q);
                if (0..3).all(|k| (1..search.dims[k] - 1).contains(&c[k]))
                    && let Some((g, clear)) = search.block_nearest(&q, c, None)
                {
                    assert_eq!(g.squared, d, "{shape:?} query {q:?} (grid)");
                    // `clear` bounds every other point's distance from below.
                    let others = (0..n)
                        .filter(|&i| i != g.index)
                        .map(|i| brute(&points[i..=i], &q))
                        .fold(f64::INFINITY, f64::min);
                    assert!(clear * clear <= others * (1.0 + 1e-12), "{clear} {others}");
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

    /// A point settling near the surface in shrinking steps (ICP's late
    /// iterations), now and then jumping: every answer, kept or searched,
    /// is the exact nearest distance and the point a fresh search finds,
    /// and most small steps keep their match.
    #[test]
    fn tracked_queries_stay_exact() {
        let points: Vec<[f64; 3]> = sample(Shape::Torus, 1024, 3)
            .iter()
            .map(|p| p.map(f64::from))
            .collect();
        let search = NearestSearch::new(points.clone());
        let starts = sample(Shape::Torus, 200, 8);
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let (mut kept, mut small) = (0, 0);
        for start in &starts {
            let mut q = start.map(|v| f64::from(v) + rng.random_range(-0.01..0.01));
            let mut track = Track::default();
            for step in 0..40 {
                // Halving from 0.05, back to 0.05 every 16 steps.
                let size = 0.05 * 0.5f64.powi(step % 16);
                let dir: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
                let len = (dir.iter().map(|v| v * v).sum::<f64>()).sqrt().max(1e-9);
                let next: [f64; 3] = std::array::from_fn(|k| q[k] + dir[k] / len * size);
                track.moved(squared(&q, &next).sqrt());
                q = next;
                let drift = track.drift;
                let found = search.nearest(&q, &mut track);
                let fresh = search.nearest(&q, &mut Track::default());
                assert_eq!(found, fresh, "query {q:?}");
                assert_eq!(found.squared, brute(&points, &q));
                if size < 1e-3 {
                    small += 1;
                    kept += usize::from(track.drift == drift && drift > 0.0);
                }
            }
        }
        assert!(kept * 2 > small, "kept {kept} of {small} small steps");
    }

    /// A single point, and all points in one place (a zero-size box).
    #[test]
    fn degenerate_templates() {
        let one = NearestSearch::new(vec![[1.0, 2.0, 3.0]]);
        assert_eq!(
            one.nearest(&[0.0, 0.0, 0.0], &mut Track::default()).index,
            0
        );
        let same = NearestSearch::new(vec![[0.5; 3]; 5]);
        let mut track = Track::default();
        same.nearest(&[0.5; 3], &mut track);
        let n = same.nearest(&[0.5, 0.5, 0.6], &mut track);
        assert!((n.squared - 0.01).abs() < 1e-12);
    }
}
