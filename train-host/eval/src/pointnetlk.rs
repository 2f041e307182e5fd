//! PointNetLK (Aoki et al., CVPR 2019), the framework's Lucas-Kanade
//! baseline, on our PointNet encoder (the f32 path of `pcrnet-core`).
//!
//! Inverse compositional: the Jacobian of the template's feature with
//! respect to a twist `xi = (omega, v)` is computed once per template by
//! finite differences, `J[:, k] = (phi(exp(d e_k) T) - phi(T)) / d`. Each
//! iteration solves `J dxi = phi(G S) - phi(T)` in the least-squares sense
//! and updates `G <- exp(dxi)^-1 G`, so that `G S` moves onto `T`.

use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3, Vector6};
use pcrnet_core::Pose;

use super::pose_from_matrix;
use pcrnet_train::net::F32Params;

/// A rigid transform in f64.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rigid64 {
    r: Matrix3<f64>,
    t: Vector3<f64>,
}

impl Rigid64 {
    const IDENTITY: Rigid64 = Rigid64 {
        r: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        t: Vector3::new(0.0, 0.0, 0.0),
    };

    /// The se(3) exponential of a twist `(omega, v)`.
    fn exp(xi: &Vector6<f64>) -> Rigid64 {
        let w = Vector3::new(xi[0], xi[1], xi[2]);
        let v = Vector3::new(xi[3], xi[4], xi[5]);
        let theta = w.norm();
        let k = w.cross_matrix();
        let (a, b) = if theta < 1e-8 {
            (0.5, 1.0 / 6.0)
        } else {
            (
                (1.0 - theta.cos()) / (theta * theta),
                (theta - theta.sin()) / (theta * theta * theta),
            )
        };
        let r = Rotation3::new(w).into_inner();
        let jl = Matrix3::identity() + k * a + k * k * b;
        Rigid64 { r, t: jl * v }
    }

    fn inverse(&self) -> Rigid64 {
        let rt = self.r.transpose();
        Rigid64 {
            r: rt,
            t: -(rt * self.t),
        }
    }

    /// `self` after `other`: `p -> self(other(p))`.
    fn after(&self, other: &Rigid64) -> Rigid64 {
        Rigid64 {
            r: self.r * other.r,
            t: self.r * other.t + self.t,
        }
    }

    fn apply(&self, pts: &[[f32; 3]]) -> Vec<[f32; 3]> {
        pts.iter()
            .map(|p| {
                let q = self.r * Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) + self.t;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect()
    }

    fn pose(&self) -> Pose {
        pose_from_matrix(&self.r, &self.t)
    }
}

/// What PointNetLK found.
#[derive(Debug, Clone, PartialEq)]
pub struct LkResult {
    /// Pose mapping the source onto the template.
    pub pose: Pose,
    /// Iterations run.
    pub iterations: usize,
    /// The pose after each iteration.
    pub trajectory: Vec<Pose>,
}

/// PointNetLK for one template: its feature and the Jacobian's pseudo-inverse.
pub struct PointNetLk<'a> {
    params: &'a F32Params,
    template_feature: DVector<f64>,
    pinv: DMatrix<f64>,
}

fn feature(params: &F32Params, cloud: &[[f32; 3]]) -> pcrnet_core::Result<DVector<f64>> {
    let f = params.encode(cloud)?;
    Ok(DVector::from_iterator(f.len(), f.iter().map(|&v| v as f64)))
}

impl<'a> PointNetLk<'a> {
    /// Prepares a template: 7 encodings (the template and 6 perturbations of
    /// size `delta`, the paper's 1e-2) and the pseudo-inverse of the Jacobian.
    pub fn new(
        params: &'a F32Params,
        template: &[[f32; 3]],
        delta: f64,
    ) -> pcrnet_core::Result<Self> {
        let phi = feature(params, template)?;
        let mut jacobian = DMatrix::zeros(phi.len(), 6);
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = delta;
            let moved = Rigid64::exp(&xi).apply(template);
            let column = (feature(params, &moved)? - &phi) / delta;
            jacobian.set_column(k, &column);
        }
        let pinv = jacobian
            .pseudo_inverse(1e-9)
            .unwrap_or_else(|_| DMatrix::zeros(6, phi.len()));
        Ok(PointNetLk {
            params,
            template_feature: phi,
            pinv,
        })
    }

    /// Registers `source` onto the template: up to `max_iterations` (the
    /// paper: 20), stopping when the update's norm is below `tolerance`.
    pub fn register(
        &self,
        source: &[[f32; 3]],
        max_iterations: usize,
        tolerance: f64,
    ) -> pcrnet_core::Result<LkResult> {
        let mut g = Rigid64::IDENTITY;
        let mut trajectory = Vec::new();
        let mut iterations = 0;
        for _ in 0..max_iterations {
            iterations += 1;
            let residual = feature(self.params, &g.apply(source))? - &self.template_feature;
            let dxi = &self.pinv * residual;
            let step = Vector6::from_iterator(dxi.iter().copied());
            g = Rigid64::exp(&step).inverse().after(&g);
            trajectory.push(g.pose());
            if step.norm() < tolerance {
                break;
            }
        }
        Ok(LkResult {
            pose: g.pose(),
            iterations,
            trajectory,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcrnet_core::Arch;
    use pcrnet_train::shapes::{Shape, sample};

    #[test]
    fn exp_and_inverse_are_consistent() {
        let xi = Vector6::new(0.1, -0.2, 0.3, 0.5, -0.1, 0.2);
        let g = Rigid64::exp(&xi);
        let id = g.inverse().after(&g);
        assert!((id.r - Matrix3::identity()).norm() < 1e-12);
        assert!(id.t.norm() < 1e-12);
        // A pure translation twist moves by v.
        let t = Rigid64::exp(&Vector6::new(0.0, 0.0, 0.0, 1.0, 2.0, 3.0));
        assert!((t.t - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-12);
    }

    #[test]
    fn undoes_a_small_motion_with_a_random_encoder() {
        let params = F32Params::init(Arch::new(&[64, 128, 512], &[8]).unwrap(), 3);
        let template = sample(Shape::Ell, 512, 3);
        let motion = Rigid64::exp(&Vector6::new(0.04, -0.03, 0.05, 0.03, -0.02, 0.01));
        let source = motion.apply(&template);
        let lk = PointNetLk::new(&params, &template, 1e-2).unwrap();
        let result = lk.register(&source, 20, 1e-7).unwrap();
        // The source was made by `motion`; the answer should be its inverse.
        let truth = motion.inverse().pose();
        let dot: f32 = result
            .pose
            .rotation
            .iter()
            .zip(truth.rotation)
            .map(|(a, b)| a * b)
            .sum();
        let angle = 2.0 * dot.abs().min(1.0).acos().to_degrees();
        let start = 2.0 * (motion.pose().rotation[0]).min(1.0).acos().to_degrees();
        assert!(
            angle < start / 2.0,
            "rotation error {angle} deg from {start} deg"
        );
        assert_eq!(result.trajectory.len(), result.iterations);
    }
}
