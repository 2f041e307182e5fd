//! PointNetLK (Aoki et al., CVPR 2019), the framework's Lucas-Kanade
//! baseline, on our PointNet encoder (the f32 path of `pcrnet-core`).
//!
//! Inverse compositional: the Jacobian of the template's feature with
//! respect to a twist `xi = (omega, v)` is computed once per template by
//! finite differences, `J[:, k] = (phi(exp(d e_k) T) - phi(T)) / d`. Each
//! iteration solves `J dxi = phi(G S) - phi(T)` in the least-squares sense
//! (the damped normal equations of [`pcrnet_train::lk::LkSolver`], as
//! PointNetLK is trained) and updates `G <- exp(dxi)^-1 G`, so that `G S`
//! moves onto `T`.

use nalgebra::DVector;
use pcrnet_core::Pose;

use super::pose_from_matrix;
use pcrnet_train::lk::{LkSolver, Rigid64, moved_templates};
use pcrnet_train::net::F32Params;

fn pose_of(g: &Rigid64) -> Pose {
    pose_from_matrix(&g.r, &g.t)
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
    /// The relative feature distance at the final pose, `||phi(G S) -
    /// phi(T)|| / ||phi(T)||`: what LK minimises, as a confidence (issue 36,
    /// item 3; [`pcrnet_core::Int8Model::feature_distance`] is the device
    /// pipeline's).
    pub feature_distance: f64,
    /// Seconds spent on `feature_distance` (one more encoder pass), for
    /// callers that time the registration alone.
    pub check_seconds: f64,
}

/// PointNetLK for one template: its feature and its solver.
pub struct PointNetLk<'a> {
    params: &'a F32Params,
    template_feature: DVector<f64>,
    solver: LkSolver,
}

fn feature(params: &F32Params, cloud: &[[f32; 3]]) -> pcrnet_core::Result<DVector<f64>> {
    let f = params.encode(cloud)?;
    Ok(DVector::from_iterator(f.len(), f.iter().map(|&v| v as f64)))
}

impl<'a> PointNetLk<'a> {
    /// `phi(G S) - phi(T)`.
    fn residual(&self, g: &Rigid64, source: &[[f32; 3]]) -> pcrnet_core::Result<DVector<f64>> {
        Ok(feature(self.params, &g.apply(source))? - &self.template_feature)
    }

    /// Prepares a template: 7 encodings (the template and its 6 moves of
    /// [`pcrnet_train::lk::JACOBIAN_STEP`]) and the solver of their
    /// Jacobian, as PointNetLK is trained ([`pcrnet_train::lk`]).
    pub fn new(params: &'a F32Params, template: &[[f32; 3]]) -> pcrnet_core::Result<Self> {
        let phi = feature(params, template)?;
        let moved = moved_templates(template)
            .iter()
            .map(|m| feature(params, m))
            .collect::<pcrnet_core::Result<Vec<_>>>()?;
        let solver = LkSolver::from_features(&phi, std::array::from_fn(|k| &moved[k]));
        Ok(PointNetLk {
            params,
            template_feature: phi,
            solver,
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
            let step = self.solver.step(&self.residual(&g, source)?);
            g = Rigid64::exp(&step).inverse().after(&g);
            trajectory.push(pose_of(&g));
            if step.norm() < tolerance {
                break;
            }
        }
        let checking = std::time::Instant::now();
        let feature_distance = self.residual(&g, source)?.norm() / self.template_feature.norm();
        Ok(LkResult {
            pose: pose_of(&g),
            iterations,
            trajectory,
            feature_distance,
            check_seconds: checking.elapsed().as_secs_f64(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use pcrnet_core::Arch;
    use pcrnet_train::shapes::{Shape, sample};

    #[test]
    fn undoes_a_small_motion_with_a_random_encoder() {
        let params = F32Params::init(Arch::new(&[64, 128, 512], &[8]).unwrap(), 3);
        let template = sample(Shape::Ell, 512, 3);
        let motion = Rigid64::exp(&Vector6::new(0.04, -0.03, 0.05, 0.03, -0.02, 0.01));
        let source = motion.apply(&template);
        let lk = PointNetLk::new(&params, &template).unwrap();
        let result = lk.register(&source, 20, 1e-7).unwrap();
        // The source was made by `motion`; the answer should be its inverse.
        let truth = pose_of(&motion.inverse());
        let dot: f32 = result
            .pose
            .rotation
            .iter()
            .zip(truth.rotation)
            .map(|(a, b)| a * b)
            .sum();
        let angle = 2.0 * dot.abs().min(1.0).acos().to_degrees();
        let start = 2.0 * (pose_of(&motion).rotation[0]).min(1.0).acos().to_degrees();
        assert!(
            angle < start / 2.0,
            "rotation error {angle} deg from {start} deg"
        );
        assert_eq!(result.trajectory.len(), result.iterations);
    }
}
