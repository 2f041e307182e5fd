//! Reducing a large source before registration (issue 10, item 5: a
//! 250 k-point depth frame went whole through the network, and a 5 M-point
//! file took minutes). The network max-pools over points and ICP uses at
//! most `max_points` of them, so a few thousand well spread points carry
//! what a registration needs.
//!
//! Every method is deterministic for a seed and keeps only finite points.

use std::collections::HashMap;

use clap::ValueEnum;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::progress::Progress;
use crate::sampling::{farthest_point_sampling_with, random_subset};

/// Points `pcrnet register` keeps by default: well above what the device
/// uses (the network sees every point it is given; ICP scores 256), small
/// enough that the host's network pass takes milliseconds.
pub const DEFAULT_SOURCE_POINTS: usize = 8192;

/// How to reduce a cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Reduction {
    /// A seeded random subset: O(N), keeps the sensor's density.
    Random,
    /// Farthest point sampling: even coverage, O(N x kept): slow on
    /// millions of points.
    Fps,
    /// One point per cube of `--voxel` units (the mean of its points),
    /// then a random subset if still too many: O(N), evens out density.
    Voxel,
}

/// `cloud`'s finite points reduced to at most `max_points` (0: no limit)
/// by `method`; `voxel` is the cube side for [`Reduction::Voxel`] (source
/// units, finite and positive), ignored otherwise.
pub fn reduce_cloud(
    cloud: &[[f32; 3]],
    method: Reduction,
    max_points: usize,
    voxel: f32,
    seed: u64,
) -> Vec<[f32; 3]> {
    let finite: Vec<[f32; 3]> = cloud
        .iter()
        .copied()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cloud = match method {
        Reduction::Voxel => voxel_means(&finite, voxel),
        _ => finite,
    };
    if max_points == 0 || cloud.len() <= max_points {
        return cloud;
    }
    match method {
        Reduction::Fps => {
            let progress = Progress::bar(max_points as u64, "farthest point sampling");
            farthest_point_sampling_with(&cloud, max_points, 0, Some(&progress))
        }
        Reduction::Random | Reduction::Voxel => random_subset(&cloud, max_points, &mut rng),
    }
}

/// The mean of the points in each cube of side `size`, in the order the
/// cubes are first met (deterministic).
fn voxel_means(cloud: &[[f32; 3]], size: f32) -> Vec<[f32; 3]> {
    if !(size.is_finite() && size > 0.0) {
        return cloud.to_vec();
    }
    let mut cells: HashMap<[i64; 3], usize> = HashMap::new();
    let mut sums: Vec<([f64; 3], u32)> = Vec::new();
    for p in cloud {
        let key = p.map(|v| (v as f64 / size as f64).floor() as i64);
        let i = *cells.entry(key).or_insert_with(|| {
            sums.push(([0.0; 3], 0));
            sums.len() - 1
        });
        if let Some((s, n)) = sums.get_mut(i) {
            for (s, &v) in s.iter_mut().zip(p) {
                *s += v as f64;
            }
            *n += 1;
        }
    }
    sums.iter()
        .map(|(s, n)| s.map(|v| (v / *n as f64) as f32))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> Vec<[f32; 3]> {
        (0..n)
            .map(|i| {
                [
                    (i % 100) as f32 * 0.01,
                    (i / 100 % 100) as f32 * 0.01,
                    (i / 10000) as f32 * 0.01,
                ]
            })
            .collect()
    }

    #[test]
    fn every_method_keeps_at_most_the_limit_deterministically() {
        let mut cloud = grid(50_000);
        cloud.push([f32::NAN, 0.0, 0.0]);
        for method in [Reduction::Random, Reduction::Fps, Reduction::Voxel] {
            let a = reduce_cloud(&cloud, method, 1000, 0.05, 7);
            assert!(a.len() <= 1000 && !a.is_empty(), "{method:?}: {}", a.len());
            assert!(a.iter().flatten().all(|v| v.is_finite()));
            assert_eq!(a, reduce_cloud(&cloud, method, 1000, 0.05, 7), "{method:?}");
        }
        // Small clouds pass untouched (finite points only); 0 is no limit.
        assert_eq!(
            reduce_cloud(&cloud[..10], Reduction::Random, 1000, 0.0, 1),
            cloud[..10]
        );
        assert_eq!(
            reduce_cloud(&cloud, Reduction::Random, 0, 0.0, 1).len(),
            50_000
        );
    }

    #[test]
    fn voxels_average_their_points() {
        let cloud = [[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.0, 0.0]];
        let out = reduce_cloud(&cloud, Reduction::Voxel, 0, 1.0, 0);
        assert_eq!(out, vec![[0.2, 0.2, 0.2], [1.5, 0.0, 0.0]]);
    }
}
