//! Training data: preprocessing a cloud and seeded (template, source)
//! pairs. The shape sets they come from are in [`super::dataset`].
//!
//! # Preprocessing (once, at load)
//! Non-finite points are dropped, the cloud is reduced to `points` points
//! (farthest point sampling from a seeded start, or a seeded random subset;
//! a smaller cloud is padded by repeating seeded random points), then
//! centred on its centroid and scaled into `[-0.5, 0.5]^3`
//! ([`crate::shapes::normalise`]).
//!
//! # Pairs
//! Template = a preprocessed shape. Source = the template under a random
//! rigid transform (Euler angles `U[-max_deg, max_deg]` per axis,
//! `R = Rz Ry Rx`, translation `U[-max_t, max_t]` per axis; with
//! `identity_share`, that share of pairs has no motion at all), optionally
//! reduced to what a depth camera at a random viewpoint sees
//! (`single_view`, see [`super::view`]), optionally
//! cropped by a random plane (keeping a fraction in `partial`), optionally
//! thinned to a random subset (a fraction in `sparse`), then padded back to
//! `points` points by repeating random kept points (max-pooling ignores
//! repeats), then perturbed by Gaussian noise of a standard deviation drawn
//! from `U[lo, hi]` (`PairConfig::noise`). The true pose maps the source onto the template:
//! `(R^T, -R^T t)`.
//!
//! # Centring (default)
//! With [`PairConfig::centre`], the finished source is then moved so its
//! centroid is at the origin (where every preprocessed template's centroid
//! is), and the true translation is adjusted to match: for the centroid
//! `c`, the source becomes `s - c` and the pose `(R^T, -R^T t + R^T c)`.
//! This is the reference implementation's `centroid_sub` (on by default in
//! `PCRNet.py` and `iterative_PCRNet.py`), and it is what makes rotation
//! learnable: uncentred, the source sits up to `sqrt(3)` away from the
//! template (translations `U[-1, 1]` per axis against a unit-box shape),
//! the max-pooled PointNet features are dominated by that offset, and a
//! 30-epoch ModelNet10 run stayed at the identity's ~42 degrees. The
//! network then only predicts the rotation and a small residual
//! translation (crops and noise move the centroid). At inference, centre
//! the source the same way ([`centre_cloud`]) and map the pose back with
//! [`uncentre_translation`].
//!
//! Every random choice comes from a ChaCha8 generator seeded by
//! [`mix_seed`] of the run seed and the pair's position, so a pair depends
//! only on (seed, epoch, slot): batches can be built in parallel and a run
//! resumes at any step without replaying a generator.

use pcrnet_io::sampling::{farthest_point_sampling, random_subset};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::geometry::{Mat3, apply, euler_to_mat, invert, mat_vec};
use crate::shapes;

/// How a cloud is reduced to the wanted number of points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Sampling {
    /// Farthest point sampling from a seeded random start.
    Fps,
    /// A seeded random subset.
    Random,
}

/// How sources are made from templates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PairConfig {
    /// Largest Euler angle per axis, degrees.
    pub max_deg: f32,
    /// Largest translation per axis.
    pub max_t: f32,
    /// Range of the noise standard deviation, drawn per pair from
    /// `U[lo, hi]` (fixed when `lo == hi`; the paper trains with `[0, 0.04]`).
    pub noise: Option<[f32; 2]>,
    /// Fraction range kept by the plane crop (partial source).
    pub partial: Option<[f32; 2]>,
    /// Fraction range kept by random thinning (sparse source).
    pub sparse: Option<[f32; 2]>,
    /// Centre the source on its centroid and adjust the true pose (see the
    /// module docs; the network then sees centred sources).
    pub centre: bool,
    /// The source is what a depth camera at a random viewpoint sees of the
    /// object ([`super::view::visible_from`], before any crop or thinning).
    #[serde(default)]
    pub single_view: bool,
    /// Share of pairs drawn at zero motion (the source is the template,
    /// crops and noise aside), so that a network learns `f(T, T) = I`.
    #[serde(default)]
    pub identity_share: f32,
}

impl PairConfig {
    /// Checks the ranges a pair can be drawn from, naming the command-line
    /// flag of a bad value: `--max-deg` in `0..=180`, `--max-t` and
    /// `--noise` finite and `>= 0`, `--partial` and `--sparse` fractions in
    /// `(0, 1]` (all finite, low <= high).
    pub fn validate(&self) -> Result<(), String> {
        if !(self.max_deg.is_finite() && (0.0..=180.0).contains(&self.max_deg)) {
            return Err(format!(
                "--max-deg must be between 0 and 180 degrees (got {})",
                self.max_deg
            ));
        }
        if !(self.max_t.is_finite() && self.max_t >= 0.0) {
            return Err(format!(
                "--max-t must be a finite number >= 0 (got {})",
                self.max_t
            ));
        }
        let range = |flag: &str, r: Option<[f32; 2]>, lo_ok: fn(f32) -> bool| match r {
            Some([lo, hi])
                if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo_ok(lo) && hi <= 1e6) =>
            {
                Err(format!(
                    "{flag} must be LO[,HI] with finite LO <= HI in range (got {lo},{hi})"
                ))
            }
            _ => Ok(()),
        };
        range("--noise", self.noise, |lo| lo >= 0.0)?;
        range("--partial", self.partial, |lo| lo > 0.0)?;
        range("--sparse", self.sparse, |lo| lo > 0.0)?;
        if !(0.0..=1.0).contains(&self.identity_share) {
            return Err(format!(
                "--identity-share must be a fraction between 0 and 1 (got {})",
                self.identity_share
            ));
        }
        for (flag, r) in [("--partial", self.partial), ("--sparse", self.sparse)] {
            if r.is_some_and(|[_, hi]| hi > 1.0) {
                return Err(format!("{flag} fractions must be at most 1"));
            }
        }
        Ok(())
    }
}

impl Default for PairConfig {
    /// The paper's: 45 degrees, translation 1, clean full sources,
    /// centred (as the reference implementation).
    fn default() -> Self {
        PairConfig {
            max_deg: 45.0,
            max_t: 1.0,
            noise: None,
            partial: None,
            sparse: None,
            centre: true,
            single_view: false,
            identity_share: 0.0,
        }
    }
}

/// A 64-bit mix of a seed and two counters (splitmix64 finaliser).
pub fn mix_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z = seed
        ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F).rotate_left(17);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Reduces (or pads) a cloud to `points` points and normalises it (see the
/// module docs). Returns `None` for a cloud without finite points.
pub fn preprocess(
    cloud: &[[f32; 3]],
    points: usize,
    sampling: Sampling,
    seed: u64,
) -> Option<Vec<[f32; 3]>> {
    let mut out = reduce(cloud, points, sampling, seed)?;
    shapes::normalise(&mut out);
    Some(out)
}

/// A preprocessed cloud and the shape's other points in its frame.
pub type KeptAndRest = (Vec<[f32; 3]>, Vec<[f32; 3]>);

/// [`preprocess`], also returning the finite points the reduction did not
/// keep, moved into the same frame (empty when every point was kept).
pub fn preprocess_split(
    cloud: &[[f32; 3]],
    points: usize,
    sampling: Sampling,
    seed: u64,
) -> Option<KeptAndRest> {
    let kept = reduce(cloud, points, sampling, seed)?;
    let mut taken: std::collections::HashMap<[u32; 3], usize> = std::collections::HashMap::new();
    for p in &kept {
        *taken.entry(p.map(f32::to_bits)).or_default() += 1;
    }
    let rest: Vec<[f32; 3]> = cloud
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .filter(|p| match taken.get_mut(&p.map(f32::to_bits)) {
            Some(n) if *n > 0 => {
                *n -= 1;
                false
            }
            _ => true,
        })
        .copied()
        .collect();
    Some(normalise_together(kept, rest))
}

/// Normalises `kept` ([`shapes::normalise`]) and moves `rest` by the same frame.
pub(super) fn normalise_together(mut kept: Vec<[f32; 3]>, mut rest: Vec<[f32; 3]>) -> KeptAndRest {
    let frame = shapes::normalising_frame(&kept);
    for p in kept.iter_mut().chain(rest.iter_mut()) {
        *p = frame.to_model(*p);
    }
    (kept, rest)
}

/// Reduces (or pads) a cloud's finite points to `points` points, keeping
/// its units. Returns `None` for a cloud without finite points.
pub fn reduce(
    cloud: &[[f32; 3]],
    points: usize,
    sampling: Sampling,
    seed: u64,
) -> Option<Vec<[f32; 3]>> {
    let finite: Vec<[f32; 3]> = cloud
        .iter()
        .copied()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    if finite.is_empty() || points == 0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = if finite.len() > points {
        match sampling {
            Sampling::Fps => {
                let start = rng.random_range(0..finite.len());
                farthest_point_sampling(&finite, points, start)
            }
            Sampling::Random => random_subset(&finite, points, &mut rng),
        }
    } else {
        finite
    };
    pad(&mut out, points, &mut rng);
    Some(out)
}

/// Pads by repeating random points of the original length.
fn pad(pts: &mut Vec<[f32; 3]>, points: usize, rng: &mut ChaCha8Rng) {
    let len = pts.len();
    while pts.len() < points {
        let i = rng.random_range(0..len);
        pts.push(pts[i]);
    }
}

/// Standard normal sample (Box-Muller).
pub fn gaussian(rng: &mut ChaCha8Rng) -> f32 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random::<f64>();
    ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
}

/// A direction uniform on the unit sphere (a normalised Gaussian vector).
fn random_direction(rng: &mut ChaCha8Rng) -> [f32; 3] {
    loop {
        let v: [f32; 3] = std::array::from_fn(|_| gaussian(rng));
        let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if norm > 1e-6 {
            break v.map(|x| x / norm);
        }
    }
}

/// One (template, source, R_gt, t_gt) pair from a preprocessed template
/// (see the module docs). The source has as many points as the template.
pub fn make_pair(
    template: &[[f32; 3]],
    cfg: &PairConfig,
    seed: u64,
) -> (Vec<[f32; 3]>, Mat3, [f32; 3]) {
    let (source, r_gt, t_gt, _) = make_pair_with_centroid(template, cfg, seed);
    (source, r_gt, t_gt)
}

/// [`make_pair`], also returning the centroid the source had before
/// centring (zero when `cfg.centre` is off): with it, a pose of the centred
/// source converts to one of the source as made ([`uncentre_translation`]).
pub fn make_pair_with_centroid(
    template: &[[f32; 3]],
    cfg: &PairConfig,
    seed: u64,
) -> (Vec<[f32; 3]>, Mat3, [f32; 3], [f32; 3]) {
    let m = make_pair_seen(template, cfg, seed);
    (m.source, m.r_gt, m.t_gt, m.centroid)
}

/// A pair as [`make_pair_seen`] makes it.
#[derive(Debug, Clone, PartialEq)]
pub struct MadePair {
    /// The source cloud.
    pub source: Vec<[f32; 3]>,
    /// True rotation, source onto template.
    pub r_gt: Mat3,
    /// True translation, source onto template.
    pub t_gt: [f32; 3],
    /// The centroid the source had before centring (zero when
    /// `cfg.centre` is off).
    pub centroid: [f32; 3],
    /// For a single-view source, where its camera stood, in the source's
    /// frame ([`super::view::eye`], moved as the source was): the
    /// viewpoint a registration of it can be checked from
    /// (`pcrnet_core::scene::View`). A crop or thinning after the view
    /// leaves it where it was.
    pub viewpoint: Option<[f32; 3]>,
}

/// [`make_pair_with_centroid`], with the single view's viewpoint.
pub fn make_pair_seen(template: &[[f32; 3]], cfg: &PairConfig, seed: u64) -> MadePair {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = template.len();
    let mut angles: [f32; 3] =
        std::array::from_fn(|_| rng.random_range(-cfg.max_deg..=cfg.max_deg).to_radians());
    let mut t: [f32; 3] = std::array::from_fn(|_| rng.random_range(-cfg.max_t..=cfg.max_t));
    // Options draw from the generator only when on, so that the pairs of
    // configurations without them stay what they were.
    if cfg.identity_share > 0.0 && rng.random::<f32>() < cfg.identity_share {
        (angles, t) = ([0.0; 3], [0.0; 3]);
    }
    let r = euler_to_mat(angles);
    let mut pts = template.to_vec();
    let mut eye = None;
    if cfg.single_view {
        let dir = random_direction(&mut rng);
        let (seen, at) = super::view::seen_from(&pts, dir);
        eye = at;
        pts = seen.into_iter().map(|i| pts[i]).collect();
    }
    if let Some([lo, hi]) = cfg.partial {
        let frac = if hi > lo {
            rng.random_range(lo..=hi)
        } else {
            lo
        };
        let d = random_direction(&mut rng);
        let keep = ((frac * n as f32).round() as usize).clamp(1, n);
        let mut order: Vec<(f32, usize)> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| (p[0] * d[0] + p[1] * d[1] + p[2] * d[2], i))
            .collect();
        order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        pts = order[..keep].iter().map(|&(_, i)| pts[i]).collect();
    }
    if let Some([lo, hi]) = cfg.sparse {
        let frac = if hi > lo {
            rng.random_range(lo..=hi)
        } else {
            lo
        };
        let keep = ((frac * pts.len() as f32).round() as usize).clamp(1, pts.len());
        pts = random_subset(&pts, keep, &mut rng);
    }
    pad(&mut pts, n, &mut rng);
    let sigma = match cfg.noise {
        Some([lo, hi]) if hi > lo => rng.random_range(lo..=hi),
        Some([lo, _]) => lo.max(0.0),
        None => 0.0,
    };
    let mut source: Vec<[f32; 3]> = pts
        .iter()
        .map(|p| {
            let q = apply(&r, &t, p);
            if sigma > 0.0 {
                q.map(|v| v + sigma * gaussian(&mut rng))
            } else {
                q
            }
        })
        .collect();
    let (r_gt, mut t_gt) = invert(&r, &t);
    let mut c = [0.0; 3];
    if cfg.centre {
        // p_template = R_gt (s' + c) + t_gt = R_gt s' + (t_gt + R_gt c).
        c = centre_cloud(&mut source);
        let rc = mat_vec(&r_gt, &c);
        t_gt = std::array::from_fn(|k| t_gt[k] + rc[k]);
    }
    let viewpoint = eye.map(|e| {
        let moved = apply(&r, &t, &e);
        std::array::from_fn(|k| moved[k] - c[k])
    });
    MadePair {
        source,
        r_gt,
        t_gt,
        centroid: c,
        viewpoint,
    }
}

/// Moves `pts` so its centroid (summed in f64) is at the origin; returns
/// the centroid it had.
pub fn centre_cloud(pts: &mut [[f32; 3]]) -> [f32; 3] {
    if pts.is_empty() {
        return [0.0; 3];
    }
    let mut sum = [0f64; 3];
    for p in pts.iter() {
        for k in 0..3 {
            sum[k] += p[k] as f64;
        }
    }
    let c = sum.map(|v| (v / pts.len() as f64) as f32);
    for p in pts.iter_mut() {
        for k in 0..3 {
            p[k] -= c[k];
        }
    }
    c
}

/// The translation of the pose between the *uncentred* clouds from the
/// pose `(r, t)` between a source centred by [`centre_cloud`] (which
/// returned `centroid`) and the template: `p -> r (p - c) + t` is
/// `p -> r p + (t - r c)`.
pub fn uncentre_translation(r: &Mat3, t: &[f32; 3], centroid: &[f32; 3]) -> [f32; 3] {
    let rc = mat_vec(r, centroid);
    std::array::from_fn(|k| t[k] - rc[k])
}

#[cfg(test)]
mod validate_tests {
    use super::PairConfig;

    #[test]
    fn bad_pair_ranges_name_their_flag() {
        assert!(PairConfig::default().validate().is_ok());
        let bad = |c: PairConfig, flag: &str| {
            let e = c.validate().unwrap_err();
            assert!(e.contains(flag), "{e}");
        };
        let d = PairConfig::default();
        bad(
            PairConfig {
                max_deg: -10.0,
                ..d
            },
            "--max-deg",
        );
        bad(
            PairConfig {
                max_deg: f32::NAN,
                ..d
            },
            "--max-deg",
        );
        bad(
            PairConfig {
                max_deg: 200.0,
                ..d
            },
            "--max-deg",
        );
        bad(
            PairConfig {
                max_t: f32::NAN,
                ..d
            },
            "--max-t",
        );
        bad(PairConfig { max_t: -1.0, ..d }, "--max-t");
        bad(
            PairConfig {
                noise: Some([0.0, f32::NAN]),
                ..d
            },
            "--noise",
        );
        bad(
            PairConfig {
                partial: Some([0.0, 0.5]),
                ..d
            },
            "--partial",
        );
        bad(
            PairConfig {
                sparse: Some([0.5, 1.5]),
                ..d
            },
            "--sparse",
        );
    }
}
