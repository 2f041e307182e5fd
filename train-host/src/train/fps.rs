//! Farthest point sampling: each pick is the point farthest from all those
//! picked so far (squared Euclidean distance; of equally far points, the
//! first in the cloud's order), starting from a given point.
//!
//! Every pick updates each point's distance to its nearest pick and takes
//! the largest: `k` passes over the cloud, `O(k n)`, which is minutes on a
//! scan of millions of points reduced to thousands (`pcrnet reduce`). The
//! pass keeps the coordinates in three arrays and eight running maxima,
//! one per lane of eight consecutive points, so the compiler can run it
//! on vectors; each distance is still `(dx dx + dy dy) + dz dz` in f32,
//! and the lanes' maxima, merged by value and then by the lowest index,
//! pick the same point as a scan in order would: the result is the
//! straightforward loop's, bit for bit (see the tests).

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
        let c = cloud[cur];
        out.push(c);
        cur = farthest(&xs, &ys, &zs, c, &mut dist);
    }
    out
}

/// Lowers each point's distance to the nearest pick by the new pick `c`
/// and returns the first point of the largest (0 if every distance is
/// NaN, as the scan in order would).
fn farthest(xs: &[f32], ys: &[f32], zs: &[f32], c: [f32; 3], dist: &mut [f32]) -> usize {
    let d2 = |x: f32, y: f32, z: f32| {
        let (dx, dy, dz) = (x - c[0], y - c[1], z - c[2]);
        dx * dx + dy * dy + dz * dz
    };
    let mut best = [-1f32; LANES];
    let mut at = [0u32; LANES];
    let groups = dist.len() / LANES;
    let (head, tail) = dist.split_at_mut(groups * LANES);
    let coords = xs
        .chunks_exact(LANES)
        .zip(ys.chunks_exact(LANES))
        .zip(zs.chunks_exact(LANES));
    for (g, (d, ((x, y), z))) in head.chunks_exact_mut(LANES).zip(coords).enumerate() {
        for l in 0..LANES {
            let v = d2(x[l], y[l], z[l]).min(d[l]);
            d[l] = v;
            let larger = v > best[l];
            best[l] = if larger { v } else { best[l] };
            at[l] = if larger {
                (g * LANES + l) as u32
            } else {
                at[l]
            };
        }
    }
    // The lanes' maxima: the largest value, then the lowest index.
    let (mut top, mut index) = (-1f32, 0usize);
    for (&v, &i) in best.iter().zip(&at) {
        if v > top || (v == top && (i as usize) < index) {
            (top, index) = (v, i as usize);
        }
    }
    // The last points, after every lane's: a scan in order.
    let base = groups * LANES;
    let rest = xs[base..].iter().zip(&ys[base..]).zip(&zs[base..]);
    for (i, (d, ((&x, &y), &z))) in tail.iter_mut().zip(rest).enumerate() {
        let v = d2(x, y, z).min(*d);
        *d = v;
        if v > top {
            (top, index) = (v, base + i);
        }
    }
    index
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
