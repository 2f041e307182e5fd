//! Single-viewpoint sources: the points of a cloud that a depth camera at
//! one viewpoint would see (issue 11, item 2). A sensor sees the surfaces
//! facing it, not a plane crop of the whole object.
//!
//! The visibility test is a point z-buffer ("splatting"): every point is
//! projected through a pinhole camera at `eye`, looking at the cloud's
//! centroid, onto a square image just covering the cloud; each pixel keeps
//! the points within one pixel's width (in depth, at that pixel's nearest
//! depth) of its nearest point. The image has about one pixel per sixteen
//! points (a 6 x 6 image for 512 points, 8 x 8 for 1,024), so that the front surface of a sampled object covers every
//! pixel it projects to and hidden points cannot show through the gaps
//! between its samples. It needs no mesh and no normals, so it applies to
//! any sampled cloud; a mesh renderer or hidden point removal (Katz et
//! al., 2007) would draw finer silhouettes.
//!
//! Deterministic: the result depends only on the cloud and the eye.

/// How far the camera stands from the cloud's centroid, in units of the
/// cloud's radius (its farthest point from the centroid): a depth camera
/// framing the object, whose perspective then sees about a third of a
/// sphere's surface (the cap where `cos > 1/3`).
pub const EYE_DISTANCE: f32 = 3.0;

/// Indices (ascending) of the points of `cloud` visible from the
/// direction `dir` (a unit vector from the centroid towards the camera):
/// the camera stands [`EYE_DISTANCE`] radii away along it. Non-finite
/// points are never visible; an empty or single-point cloud keeps what it
/// has.
pub fn visible_from(cloud: &[[f32; 3]], dir: [f32; 3]) -> Vec<usize> {
    seen_from(cloud, dir).0
}

/// [`visible_from`] and [`eye`] at once: the visible points' indices and
/// where the camera stood, with one pass for the camera.
pub fn seen_from(cloud: &[[f32; 3]], dir: [f32; 3]) -> (Vec<usize>, Option<[f32; 3]>) {
    let finite: Vec<usize> = (0..cloud.len())
        .filter(|&i| cloud[i].iter().all(|v| v.is_finite()))
        .collect();
    if finite.len() < 2 {
        return (finite, None);
    }
    let Some((eye, f)) = camera(cloud, dir) else {
        return (finite, None);
    };
    // An image basis perpendicular to the viewing direction.
    let helper = if f[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let Some(u) = normalised(cross(f, helper)) else {
        return (finite, Some(eye));
    };
    let w = cross(f, u);
    // Project: image coordinates (x, y) = lateral / depth, and the depth.
    let projected: Vec<(usize, f32, f32, f32)> = finite
        .iter()
        .map(|&i| {
            let v = sub(cloud[i], eye);
            let z = dot(v, f);
            (i, dot(v, u) / z, dot(v, w) / z, z)
        })
        .collect();
    let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
    for &(_, x, y, _) in &projected {
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    let side = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f32::MIN_POSITIVE);
    let grid = ((finite.len() as f32 / 16.0).sqrt().round() as usize).max(4);
    let pixel = |x: f32, y: f32| -> usize {
        let cell = |t: f32, lo: f32| (((t - lo) / side * grid as f32) as usize).min(grid - 1);
        cell(y, lo[1]) * grid + cell(x, lo[0])
    };
    let mut nearest = vec![f32::INFINITY; grid * grid];
    for &(_, x, y, z) in &projected {
        let p = pixel(x, y);
        nearest[p] = nearest[p].min(z);
    }
    // One pixel's width at the pixel's nearest depth.
    let width = side / grid as f32;
    let seen = projected
        .iter()
        .filter(|&&(_, x, y, z)| {
            let near = nearest[pixel(x, y)];
            z <= near + width * near
        })
        .map(|&(i, ..)| i)
        .collect();
    (seen, Some(eye))
}

/// Where the camera of [`visible_from`] stands for `cloud` and `dir`
/// (the cloud's frame): [`EYE_DISTANCE`] radii from the centroid of the
/// finite points along `dir`. `None` when it has none (fewer than two
/// finite points, all at one place, or a zero `dir`). For a view made by
/// `visible_from(cloud, dir)` this is the sensor's viewpoint, what
/// `pcrnet_core::scene::View` checks a registration from.
pub fn eye(cloud: &[[f32; 3]], dir: [f32; 3]) -> Option<[f32; 3]> {
    camera(cloud, dir).map(|(eye, _)| eye)
}

/// The camera of [`visible_from`]: its position and its unit viewing
/// direction (from the eye towards the centroid).
fn camera(cloud: &[[f32; 3]], dir: [f32; 3]) -> Option<([f32; 3], [f32; 3])> {
    let points: Vec<[f32; 3]> = cloud
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .copied()
        .collect();
    if points.len() < 2 {
        return None;
    }
    let c = pcrnet_core::pose::centroid(&points).ok()?;
    let radius = points.iter().map(|&p| norm(sub(p, c))).fold(0f32, f32::max);
    let f = normalised(dir.map(|v| -v))?;
    if radius <= 0.0 {
        return None;
    }
    Some(([0, 1, 2].map(|k| c[k] - f[k] * EYE_DISTANCE * radius), f))
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

fn normalised(a: [f32; 3]) -> Option<[f32; 3]> {
    let n = norm(a);
    (n > 1e-12 && n.is_finite()).then(|| a.map(|v| v / n))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` points evenly over the unit sphere (Fibonacci lattice).
    fn sphere(n: usize) -> Vec<[f32; 3]> {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - y * y).sqrt();
                let a = golden * i as f32;
                [r * a.cos(), y, r * a.sin()]
            })
            .collect()
    }

    #[test]
    fn a_sphere_shows_the_cap_facing_the_camera() {
        for (s, dir) in [512, 1024, 2048].map(sphere).into_iter().flat_map(|s| {
            [[0.0, 0.0, 1.0], [0.6, -0.8, 0.0], [-0.48, 0.6, 0.64]].map(|d| (s.clone(), d))
        }) {
            let seen = visible_from(&s, dir);
            // From 3 radii, the visible cap is cos > 1/3, a third of the
            // points; near its rim the surface grazes the view and the
            // z-buffer keeps fewer.
            let share = seen.len() as f32 / s.len() as f32;
            assert!((0.2..0.4).contains(&share), "{dir:?}: {share}");
            for &i in &seen {
                assert!(
                    dot(s[i], dir) > 0.0,
                    "{dir:?}: point {i} faces away: {}",
                    dot(s[i], dir)
                );
            }
            // Everything squarely facing the camera is kept.
            let facing: Vec<usize> = (0..s.len()).filter(|&i| dot(s[i], dir) > 0.6).collect();
            let kept = facing.iter().filter(|i| seen.contains(i)).count();
            assert!(
                kept as f32 >= 0.97 * facing.len() as f32,
                "{dir:?}: {kept} of {}",
                facing.len()
            );
            assert!(seen.windows(2).all(|w| w[0] < w[1]));
        }
    }

    #[test]
    fn the_far_face_of_a_box_is_hidden() {
        // Points on the six faces of the unit cube, 16 x 16 a face.
        let mut b = Vec::new();
        for a in 0..16 {
            for c in 0..16 {
                let (s, t) = ((a as f32 + 0.5) / 16.0 - 0.5, (c as f32 + 0.5) / 16.0 - 0.5);
                for p in [
                    [s, t, 0.5],
                    [s, t, -0.5],
                    [s, 0.5, t],
                    [s, -0.5, t],
                    [0.5, s, t],
                    [-0.5, s, t],
                ] {
                    b.push(p);
                }
            }
        }
        let seen = visible_from(&b, [0.0, 0.0, 1.0]);
        let front = seen.iter().filter(|&&i| b[i][2] == 0.5).count();
        let back = seen.iter().filter(|&&i| b[i][2] == -0.5).count();
        assert_eq!(back, 0);
        assert!(front >= 240, "{front} of 256 front points");
    }

    #[test]
    fn degenerate_clouds_keep_their_finite_points() {
        assert!(visible_from(&[], [0.0, 0.0, 1.0]).is_empty());
        assert_eq!(visible_from(&[[1.0, 2.0, 3.0]], [0.0, 0.0, 1.0]), [0]);
        let same = vec![[1.0, 1.0, 1.0]; 5];
        assert_eq!(visible_from(&same, [0.0, 0.0, 1.0]).len(), 5);
        let with_nan = [[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]];
        assert!(!visible_from(&with_nan, [0.0, 1.0, 0.0]).contains(&1));
    }
}
