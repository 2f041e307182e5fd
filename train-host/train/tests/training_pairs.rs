//! Training pairs: the true pose maps the source onto the template,
//! centring keeps it, crops, thinning, noise and sampling behave as
//! configured, single-view and identity pairs, all seeded.

use pcrnet_train::geometry::apply;
use pcrnet_train::{Dataset, PairConfig, Sampling, data, rotation_error_deg};

/// Centring moves the source onto its centroid and adjusts the true pose:
/// the centred pair is the uncentred one shifted, the true pose still maps
/// the source onto the template, [`data::uncentre_translation`] gives back
/// the uncentred pose, and a perfect predictor scores zero error.
#[test]
fn centred_pairs_keep_the_pose() {
    let ds = Dataset::generated(2, 100, 8);
    let tpl = &ds.clouds[1];
    let cfg = PairConfig {
        noise: Some([0.0, 0.02]),
        partial: Some([0.5, 0.8]),
        ..PairConfig::default()
    };
    let raw_cfg = PairConfig {
        centre: false,
        ..cfg
    };
    let (src, r, t) = data::make_pair(tpl, &cfg, 11);
    let (mut raw, r_raw, t_raw) = data::make_pair(tpl, &raw_cfg, 11);
    assert_eq!(r, r_raw);
    let c = data::centre_cloud(&mut raw);
    assert!(
        c.iter().map(|v| v * v).sum::<f32>() > 1e-4,
        "source was off-centre"
    );
    for (a, b) in src.iter().zip(&raw) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-6);
        }
    }
    let back = data::uncentre_translation(&r, &t, &c);
    for k in 0..3 {
        assert!((back[k] - t_raw[k]).abs() < 1e-5, "{back:?} vs {t_raw:?}");
    }
    // Clean full pair: the true pose maps the centred source onto the template.
    let (src, r, t) = data::make_pair(tpl, &PairConfig::default(), 12);
    let mean: Vec<f32> = (0..3)
        .map(|k| src.iter().map(|p| p[k]).sum::<f32>() / src.len() as f32)
        .collect();
    assert!(mean.iter().all(|m| m.abs() < 1e-5), "centroid {mean:?}");
    for (p, q) in src.iter().zip(tpl) {
        let b = apply(&r, &t, p);
        for k in 0..3 {
            assert!((b[k] - q[k]).abs() < 1e-5);
        }
    }
    // Validation compares the estimate with this same pose: a perfect
    // predictor scores zero.
    let s = pcrnet_train::Summary::of(
        &[rotation_error_deg(&r, &r)],
        &[pcrnet_train::translation_error(&t, &t)],
        None,
    );
    assert!(
        s.rotation_deg.mean < 1e-2 && s.translation.mean < 1e-6,
        "{s:?}"
    );
}

/// The true pose of a clean pair maps the source exactly onto the template;
/// crops, thinning and noise behave as configured; everything is seeded.
#[test]
fn pairs_and_preprocessing() {
    let ds = Dataset::generated(3, 200, 3);
    for c in &ds.clouds {
        assert_eq!(c.len(), 200);
        let max = c.iter().flatten().fold(0f32, |m, v| m.max(v.abs()));
        assert!((max - 0.5).abs() < 1e-5);
    }
    let tpl = &ds.clouds[0];
    let (src, r, t) = data::make_pair(tpl, &PairConfig::default(), 42);
    for (p, q) in src.iter().zip(tpl) {
        let back = apply(&r, &t, p);
        for k in 0..3 {
            assert!((back[k] - q[k]).abs() < 1e-5);
        }
    }
    assert_eq!(data::make_pair(tpl, &PairConfig::default(), 42).0, src);
    assert_ne!(data::make_pair(tpl, &PairConfig::default(), 43).0, src);
    // Partial: about half the template's points survive (repeats pad it back).
    let cfg = PairConfig {
        partial: Some([0.5, 0.5]),
        ..PairConfig::default()
    };
    let (src, r, t) = data::make_pair(tpl, &cfg, 1);
    assert_eq!(src.len(), 200);
    let mut distinct: Vec<[u32; 3]> = src
        .iter()
        .map(|p| apply(&r, &t, p).map(|v| (v * 1e4).round().to_bits()))
        .collect();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), 100);
    // Noise: the registered source is off the template by about sigma.
    let cfg = PairConfig {
        noise: Some([0.0, 0.04]),
        ..PairConfig::default()
    };
    let (src, r, t) = data::make_pair(tpl, &cfg, 3);
    let rms = (src
        .iter()
        .zip(tpl)
        .map(|(p, q)| {
            let b = apply(&r, &t, p);
            (0..3).map(|k| (b[k] - q[k]).powi(2)).sum::<f32>()
        })
        .sum::<f32>()
        / 600.0)
        .sqrt();
    assert!(rms > 1e-4 && rms < 0.05, "noise rms {rms}");
    // Farthest point sampling spreads points: its subset covers the box.
    let fps = pcrnet_io::sampling::farthest_point_sampling(tpl, 16, 0);
    assert_eq!(fps.len(), 16);
    let pre = data::preprocess(tpl, 50, Sampling::Fps, 1).unwrap();
    assert_eq!(pre.len(), 50);
    assert_eq!(pre, data::preprocess(tpl, 50, Sampling::Fps, 1).unwrap());
}

/// Issue 11, items 2 and 3: single-view sources keep only what a camera
/// sees (padded back to the template's size), identity pairs have no
/// motion, and both are seeded like every other choice.
#[test]
fn single_view_and_identity_pairs() {
    let ds = Dataset::generated(3, 512, 5);
    let tpl = &ds.clouds[0];
    let distinct = |c: &[[f32; 3]]| {
        let mut v: Vec<[u32; 3]> = c.iter().map(|p| p.map(f32::to_bits)).collect();
        v.sort_unstable();
        v.dedup();
        v.len()
    };
    let view = PairConfig {
        single_view: true,
        centre: false,
        ..PairConfig::default()
    };
    let (src, r, t) = data::make_pair(tpl, &view, 3);
    assert_eq!(src.len(), tpl.len());
    let seen = distinct(&src);
    assert!(
        seen > 50 && seen < tpl.len() * 3 / 4,
        "{seen} distinct points"
    );
    // Every source point is a template point moved by the pose's inverse.
    for s in &src {
        let back = apply(&r, &t, s);
        let nearest = tpl
            .iter()
            .map(|p| (0..3).map(|k| (p[k] - back[k]).powi(2)).sum::<f32>())
            .fold(f32::INFINITY, f32::min);
        assert!(nearest < 1e-9, "{back:?}");
    }
    assert_eq!(data::make_pair(tpl, &view, 3).0, src);

    let still = PairConfig {
        identity_share: 1.0,
        centre: false,
        ..PairConfig::default()
    };
    let (src, r, t) = data::make_pair(tpl, &still, 4);
    assert_eq!(&src, tpl);
    assert_eq!(t, [0.0; 3]);
    assert_eq!(
        rotation_error_deg(&r, &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        0.0
    );
    let half = PairConfig {
        identity_share: 0.5,
        ..PairConfig::default()
    };
    let still = (0..200)
        .filter(|&s| data::make_pair(tpl, &half, s).2 == [0.0; 3])
        .count();
    assert!(
        (70..130).contains(&still),
        "{still} of 200 pairs without motion"
    );
    for bad in [1.5f32, -0.1, f32::NAN] {
        let cfg = PairConfig {
            identity_share: bad,
            ..PairConfig::default()
        };
        assert!(
            cfg.validate()
                .is_err_and(|e| e.contains("--identity-share"))
        );
    }
}

/// A single-view pair says where its camera stood (`MadePair::viewpoint`,
/// in the source's frame, centred or not): moved by the true pose it lies
/// `view::EYE_DISTANCE` radii from the template's centroid, on the side
/// the source was seen from (nearer the seen points than the unseen).
/// Other pairs have none.
#[test]
fn single_view_pairs_carry_their_viewpoint() {
    use pcrnet_train::view::EYE_DISTANCE;
    let ds = Dataset::generated(3, 512, 5);
    let tpl = &ds.clouds[0];
    let mean = |c: &[[f32; 3]]| -> [f32; 3] {
        std::array::from_fn(|k| c.iter().map(|p| p[k]).sum::<f32>() / c.len() as f32)
    };
    let dist = |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
    let c = mean(tpl);
    let radius = tpl.iter().map(|&p| dist(p, c)).fold(0f32, f32::max);
    for centre in [false, true] {
        let cfg = PairConfig {
            single_view: true,
            centre,
            noise: Some([0.01, 0.01]),
            ..PairConfig::default()
        };
        let made = data::make_pair_seen(tpl, &cfg, 7);
        let (src, _, _) = data::make_pair(tpl, &cfg, 7);
        assert_eq!(made.source, src, "the same pair");
        let eye = apply(
            &made.r_gt,
            &made.t_gt,
            &made.viewpoint.expect("a viewpoint"),
        );
        let d = dist(eye, c);
        assert!(
            (d - EYE_DISTANCE * radius).abs() < 1e-3 * d,
            "{d} vs {radius}"
        );
        let seen: Vec<[f32; 3]> = src
            .iter()
            .map(|s| apply(&made.r_gt, &made.t_gt, s))
            .collect();
        let near = |p: [f32; 3]| dist(p, eye);
        let seen_mean = seen.iter().map(|&p| near(p)).sum::<f32>() / seen.len() as f32;
        let all_mean = tpl.iter().map(|&p| near(p)).sum::<f32>() / tpl.len() as f32;
        assert!(seen_mean < all_mean, "{seen_mean} vs {all_mean}");
    }
    let plain = data::make_pair_seen(tpl, &PairConfig::default(), 7);
    assert_eq!(plain.viewpoint, None);
}
