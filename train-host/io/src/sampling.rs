//! Sampling a cloud down to `k` of its points: a seeded random subset
//! ([`random_subset`]), or farthest point sampling: each pick is the point farthest from all those
//! picked so far (squared Euclidean distance; of equally far points, the
//! first in the cloud's order), starting from a given point.
//!
//! Every pick updates each point's distance to its nearest pick and takes
//! the largest: `k` passes over the cloud, `O(k n)`, which is minutes on a
//! scan of millions of points reduced to thousands (`pcrnet reduce`). The
//! pass keeps the coordinates in three arrays and eight running maxima,
//! one per lane of eight consecutive points, so the compiler can run it
//! on vectors; each distance is still `(dx dx + dy dy) + dz dz` in f32,
//! and the first point at the largest distance, found by a second,
//! early-stopping pass, is the one a scan in order would pick: the result
//! is the straightforward loop's, bit for bit (see the tests).

use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Points per group of running maxima.
const LANES: usize = 8;

/// Farthest point sampling: `k` points of `cloud` (all of them, in pick
/// order, when it has fewer), starting from point `start % cloud.len()`.
pub fn farthest_point_sampling(cloud: &[[f32; 3]], k: usize, start: usize) -> Vec<[f32; 3]> {
    farthest_point_sampling_with(cloud, k, start, None)
}

/// [`farthest_point_sampling`], counting each point picked on `progress`.
pub fn farthest_point_sampling_with(
    cloud: &[[f32; 3]],
    k: usize,
    start: usize,
    progress: Option<&crate::progress::Progress>,
) -> Vec<[f32; 3]> {
    farthest_point_indices(cloud, k, start, progress)
        .into_iter()
        .map(|i| cloud[i])
        .collect()
}

/// The indices into `cloud` of the points [`farthest_point_sampling_with`]
/// picks, in pick order. Once every point lies at distance 0 from a pick
/// (a cloud with fewer distinct points than `k`), indices repeat.
pub fn farthest_point_indices(
    cloud: &[[f32; 3]],
    k: usize,
    start: usize,
    progress: Option<&crate::progress::Progress>,
) -> Vec<usize> {
    if cloud.is_empty() || k == 0 {
        return Vec::new();
    }
    let axis = |a: usize| -> Vec<f32> { cloud.iter().map(|p| p[a]).collect() };
    let (xs, ys, zs) = (axis(0), axis(1), axis(2));
    let mut out = Vec::with_capacity(k.min(cloud.len()));
    let mut dist = vec![f32::INFINITY; cloud.len()];
    let mut cur = start % cloud.len();
    for _ in 0..k.min(cloud.len()) {
        if let Some(p) = progress {
            p.inc(1);
        }
        out.push(cur);
        cur = farthest(&xs, &ys, &zs, cloud[cur], &mut dist);
    }
    out
}

/// Lowers each point's distance to the nearest pick by the new pick `c`
/// and returns the first point of the largest (0 if every distance is
/// NaN, as the scan in order would).
///
/// Two passes: the first lowers the distances and keeps the largest per
/// lane, values only, so the compiler keeps both on vectors (carrying each
/// lane's index as well left it scalar); the second finds the first point
/// at that distance, which is the point a scan in order picks.
fn farthest(xs: &[f32], ys: &[f32], zs: &[f32], c: [f32; 3], dist: &mut [f32]) -> usize {
    let d2 = |x: f32, y: f32, z: f32| {
        let (dx, dy, dz) = (x - c[0], y - c[1], z - c[2]);
        dx * dx + dy * dy + dz * dz
    };
    let mut best = [-1f32; LANES];
    let groups = dist.len() / LANES;
    let (head, tail) = dist.split_at_mut(groups * LANES);
    let coords = xs
        .chunks_exact(LANES)
        .zip(ys.chunks_exact(LANES))
        .zip(zs.chunks_exact(LANES));
    for (d, ((x, y), z)) in head.chunks_exact_mut(LANES).zip(coords) {
        for l in 0..LANES {
            let v = lower(d2(x[l], y[l], z[l]), d[l]);
            d[l] = v;
            best[l] = if v > best[l] { v } else { best[l] };
        }
    }
    let mut top = best.iter().fold(-1f32, |t, &v| if v > t { v } else { t });
    // The last points, after every lane's.
    let base = groups * LANES;
    let rest = xs[base..].iter().zip(&ys[base..]).zip(&zs[base..]);
    for (d, ((&x, &y), &z)) in tail.iter_mut().zip(rest) {
        let v = lower(d2(x, y, z), *d);
        *d = v;
        if v > top {
            top = v;
        }
    }
    // A group of eight at a time (compared on vectors), then the point in it.
    let group = dist
        .chunks(LANES)
        .position(|g| g.iter().fold(false, |hit, &v| hit | (v == top)))
        .unwrap_or(0);
    let first = group * LANES;
    dist.get(first..)
        .and_then(|d| d.iter().position(|&v| v == top))
        .map_or(0, |i| first + i)
}

/// `new.min(old)` for a distance `old` that is never NaN (it starts
/// infinite and only takes values from here): a NaN `new` keeps `old`, as
/// `f32::min` would, but as one compare and select (`MINPS`) instead of
/// `f32::min`'s NaN fix-up around it.
#[inline(always)]
fn lower(new: f32, old: f32) -> f32 {
    if new < old { new } else { old }
}

/// `k` distinct points of `cloud` in a random order (partial Fisher-Yates).
pub fn random_subset(cloud: &[[f32; 3]], k: usize, rng: &mut ChaCha8Rng) -> Vec<[f32; 3]> {
    let mut idx: Vec<usize> = (0..cloud.len()).collect();
    let k = k.min(idx.len());
    for i in 0..k {
        let j = rng.random_range(i..idx.len());
        idx.swap(i, j);
    }
    idx[..k].iter().map(|&i| cloud[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The scan in order that the lanes must reproduce.
    fn plain(cloud: &[[f32; 3]], k: usize, start: usize) -> Vec<[f32; 3]> {
        let d2 = |a: &[f32; 3], b: &[f32; 3]| {
            (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
        };
        let mut out = Vec::new();
        let mut dist = vec![f32::INFINITY; cloud.len()];
        let mut cur = start % cloud.len();
        for _ in 0..k.min(cloud.len()) {
            out.push(cloud[cur]);
            let c = cloud[cur];
            let mut best = (0usize, -1f32);
            for (i, p) in cloud.iter().enumerate() {
                let d = d2(p, &c).min(dist[i]);
                dist[i] = d;
                if d > best.1 {
                    best = (i, d);
                }
            }
            cur = best.0;
        }
        out
    }

    /// Bit for bit the scan in order: clouds shorter than a lane group and
    /// longer, with repeated points and points on a coarse grid (many equal
    /// distances: the first of them must win), and with a NaN coordinate.
    #[test]
    fn picks_as_the_scan_in_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for n in [1, 5, 8, 9, 63, 64, 200, 1000] {
            let random: Vec<[f32; 3]> = (0..n)
                .map(|_| [0; 3].map(|_: i32| rng.random_range(-1.0..1.0)))
                .collect();
            let grid: Vec<[f32; 3]> = (0..n)
                .map(|_| [0; 3].map(|_: i32| rng.random_range(0..4) as f32))
                .collect();
            let mut repeated = random.clone();
            for i in (0..n).step_by(3) {
                repeated[i] = random[i / 2];
            }
            let mut with_nan = random.clone();
            with_nan[n / 2][1] = f32::NAN;
            for (what, cloud) in [
                ("random", random),
                ("grid", grid),
                ("repeated", repeated),
                ("nan", with_nan),
            ] {
                for (k, start) in [(n, 0), (n / 2 + 1, 7), (3 * n, n / 3)] {
                    let want = plain(&cloud, k, start);
                    let got = farthest_point_sampling(&cloud, k, start);
                    let bits = |v: &[[f32; 3]]| -> Vec<[u32; 3]> {
                        v.iter().map(|p| p.map(f32::to_bits)).collect()
                    };
                    assert_eq!(
                        bits(&got),
                        bits(&want),
                        "{what}, {n} points, {k} from {start}"
                    );
                }
            }
        }
        assert!(farthest_point_sampling(&[], 3, 0).is_empty());
        assert!(farthest_point_sampling(&[[0.0; 3]], 0, 0).is_empty());
    }
}
