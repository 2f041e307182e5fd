//! Point-to-point ICP (Besl & McKay), the paper's baseline: exact nearest
//! neighbours ([`super::nearest`]: a grid, a `kiddo` k-d tree for far
//! queries, each source point's match kept without a search while it
//! provably stands), the rigid update by the Kabsch / SVD method (`nalgebra`), in
//! f64.

use nalgebra::{Matrix3, Vector3};
use pcrnet_core::Pose;

use super::nearest::{NearestSearch, Track};
use super::pose_from_matrix;

/// ICP settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpConfig {
    /// Most iterations (the paper: 100).
    pub max_iterations: usize,
    /// Stop when the mean squared nearest-neighbour distance changes by less than this.
    pub tolerance: f64,
}

impl Default for IcpConfig {
    fn default() -> Self {
        IcpConfig {
            max_iterations: 100,
            tolerance: 1e-10,
        }
    }
}

/// What ICP found.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpResult {
    /// Pose mapping the source onto the template.
    pub pose: Pose,
    /// Iterations run.
    pub iterations: usize,
    /// Mean squared nearest-neighbour distance after the last update.
    pub mse: f64,
    /// The pose after each iteration (for convergence plots).
    pub trajectory: Vec<Pose>,
}

/// Why ICP could not run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IcpError {
    /// A cloud has no points.
    #[error("ICP needs non-empty clouds")]
    EmptyCloud,
    /// A coordinate is NaN or infinite.
    #[error("ICP input has a non-finite coordinate")]
    NonFinite,
}

fn to_vec(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// The rigid transform minimising `sum |R a_i + t - b_i|^2` (Kabsch).
fn kabsch(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> (Matrix3<f64>, Vector3<f64>) {
    let n = a.len() as f64;
    let ca = a.iter().sum::<Vector3<f64>>() / n;
    let cb = b.iter().sum::<Vector3<f64>>() / n;
    let h = a.iter().zip(b).fold(Matrix3::zeros(), |h, (p, q)| {
        h + (p - ca) * (q - cb).transpose()
    });
    let svd = h.svd(true, true);
    let (u, v_t) = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => (u, v_t),
        _ => return (Matrix3::identity(), cb - ca),
    };
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    (r, cb - r * ca)
}

/// Registers `source` onto `template` with point-to-point ICP from the identity.
pub fn icp(
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    config: IcpConfig,
) -> Result<IcpResult, IcpError> {
    if template.is_empty() || source.is_empty() {
        return Err(IcpError::EmptyCloud);
    }
    if template
        .iter()
        .chain(source)
        .flatten()
        .any(|v| !v.is_finite())
    {
        return Err(IcpError::NonFinite);
    }
    let search = NearestSearch::new(template.iter().map(|p| p.map(f64::from)).collect());
    let mut moved: Vec<Vector3<f64>> = source.iter().map(to_vec).collect();
    let (mut r, mut t) = (Matrix3::identity(), Vector3::zeros());
    let mut previous = f64::INFINITY;
    let mut mse = f64::INFINITY;
    let mut trajectory = Vec::new();
    let mut matched = vec![Vector3::zeros(); moved.len()];
    // What each source point's last search found, and how far it has moved since.
    let mut tracks = vec![Track::default(); moved.len()];
    for iteration in 1..=config.max_iterations {
        let mut sum = 0.0;
        for ((m, track), p) in matched.iter_mut().zip(&mut tracks).zip(&moved) {
            let nn = search.nearest(&[p.x, p.y, p.z], track);
            sum += nn.squared;
            *m = Vector3::from(search.point(nn.index));
        }
        let (dr, dt) = kabsch(&moved, &matched);
        for (p, track) in moved.iter_mut().zip(&mut tracks) {
            let next = dr * *p + dt;
            track.moved((next - *p).norm());
            *p = next;
        }
        r = dr * r;
        t = dr * t + dt;
        trajectory.push(pose_from_matrix(&r, &t));
        mse = sum / moved.len() as f64;
        if (previous - mse).abs() < config.tolerance {
            return Ok(IcpResult {
                pose: pose_from_matrix(&r, &t),
                iterations: iteration,
                mse,
                trajectory,
            });
        }
        previous = mse;
    }
    Ok(IcpResult {
        pose: pose_from_matrix(&r, &t),
        iterations: config.max_iterations,
        mse,
        trajectory,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcrnet_train::shapes::{Shape, random_transform, sample};

    #[test]
    fn recovers_a_small_transform() {
        let template = sample(Shape::Ell, 512, 3);
        // Small motion (ICP's basin of convergence): 10 degrees, 0.05.
        let source = random_transform(&template, 10.0, 0.05, 4);
        let result = icp(&template, &source, IcpConfig::default()).unwrap();
        // Applying the found pose to the source must land on the template
        // point for point (the source is an exact copy, same order).
        let worst = source
            .iter()
            .zip(&template)
            .map(|(s, t)| {
                let p = result.pose.transform_point(*s);
                ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2) + (p[2] - t[2]).powi(2)).sqrt()
            })
            .fold(0f32, f32::max);
        assert!(worst < 1e-3, "worst residual {worst}");
        assert!(result.mse < 1e-8);
        assert_eq!(result.trajectory.len(), result.iterations);
    }

    #[test]
    fn kabsch_is_exact_on_correspondences() {
        let a: Vec<Vector3<f64>> = sample(Shape::Torus, 50, 1).iter().map(to_vec).collect();
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 1.2);
        let b: Vec<Vector3<f64>> = a
            .iter()
            .map(|p| rot * p + Vector3::new(0.1, 0.2, -0.3))
            .collect();
        let (r, t) = kabsch(&a, &b);
        assert!((r - rot.matrix()).norm() < 1e-9);
        assert!((t - Vector3::new(0.1, 0.2, -0.3)).norm() < 1e-9);
    }

    #[test]
    fn bad_input_is_an_error() {
        let t = sample(Shape::Box, 10, 1);
        assert_eq!(
            icp(&t, &[], IcpConfig::default()),
            Err(IcpError::EmptyCloud)
        );
        assert_eq!(
            icp(&t, &[[f32::NAN, 0.0, 0.0]], IcpConfig::default()),
            Err(IcpError::NonFinite)
        );
    }
}
