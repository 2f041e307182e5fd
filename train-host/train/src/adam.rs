//! Adam and the learning-rate schedule.

use serde::{Deserialize, Serialize};

use crate::F32Params;

/// Learning-rate schedule, a pure function of the step (so a resumed run
/// follows the same curve).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Schedule {
    /// The base rate throughout.
    Constant,
    /// Multiply by `gamma` every `every_epochs` epochs.
    Step {
        /// Epochs between decays.
        every_epochs: usize,
        /// Factor per decay.
        gamma: f32,
    },
    /// Cosine from the base rate down to `min_factor x` base over the whole run.
    Cosine {
        /// Final rate as a fraction of the base rate.
        min_factor: f32,
    },
}

impl Schedule {
    /// Learning rate at `step` (0-based) of `total_steps`, with
    /// `steps_per_epoch` steps per epoch.
    pub fn rate(self, base: f32, step: usize, steps_per_epoch: usize, total_steps: usize) -> f32 {
        match self {
            Schedule::Constant => base,
            Schedule::Step {
                every_epochs,
                gamma,
            } => {
                let epoch = step / steps_per_epoch.max(1);
                base * gamma.powi((epoch / every_epochs.max(1)) as i32)
            }
            Schedule::Cosine { min_factor } => {
                let p = step as f64 / total_steps.max(1) as f64;
                let c = 0.5 * (1.0 + (std::f64::consts::PI * p.min(1.0)).cos());
                (base as f64 * (min_factor as f64 + (1.0 - min_factor as f64) * c)) as f32
            }
        }
    }
}

/// Adam state (Kingma & Ba), one moment pair per parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    /// Decay of the first moment.
    pub beta1: f32,
    /// Decay of the second moment.
    pub beta2: f32,
    /// Denominator guard.
    pub eps: f32,
    /// Updates done.
    pub t: u64,
    /// First moments, per layer (weights then bias, flattened).
    pub m: Vec<Vec<f32>>,
    /// Second moments, same layout.
    pub v: Vec<Vec<f32>>,
}

impl Adam {
    /// Zero state for `params` with the usual constants (0.9, 0.999, 1e-8).
    pub fn new(params: &F32Params) -> Self {
        let zeros: Vec<Vec<f32>> = params
            .layers
            .iter()
            .map(|(w, b)| vec![0.0; w.len() + b.len()])
            .collect();
        Adam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            t: 0,
            m: zeros.clone(),
            v: zeros,
        }
    }

    /// One update with learning rate `lr`. Element-wise, so deterministic.
    pub fn update(&mut self, params: &mut F32Params, grads: &F32Params, lr: f32) {
        use rayon::prelude::*;
        self.t += 1;
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        let c1 = 1.0 - b1.powi(self.t.min(i32::MAX as u64) as i32);
        let c2 = 1.0 - b2.powi(self.t.min(i32::MAX as u64) as i32);
        let step = lr * c2.sqrt() / c1;
        for (((p, g), m), v) in params
            .layers
            .iter_mut()
            .zip(&grads.layers)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            let nw = p.0.len();
            let (mw, mb) = m.split_at_mut(nw);
            let (vw, vb) = v.split_at_mut(nw);
            for (p, g, m, v) in [(&mut p.0, &g.0, mw, vw), (&mut p.1, &g.1, mb, vb)] {
                p.par_iter_mut()
                    .zip(g.par_iter())
                    .zip(m.par_iter_mut())
                    .zip(v.par_iter_mut())
                    .for_each(|(((p, &g), m), v)| {
                        *m = b1 * *m + (1.0 - b1) * g;
                        *v = b2 * *v + (1.0 - b2) * g * g;
                        *p -= step * *m / (v.sqrt() + eps);
                    });
            }
        }
    }
}

/// Global L2 norm of a gradient (f64, in layer order).
pub fn grad_norm(grads: &F32Params) -> f64 {
    grads
        .layers
        .iter()
        .flat_map(|(w, b)| w.iter().chain(b))
        .map(|&g| (g as f64) * (g as f64))
        .sum::<f64>()
        .sqrt()
}

/// Scales the gradient so its global norm is at most `max_norm`.
pub fn clip_grad_norm(grads: &mut F32Params, max_norm: f32) -> f64 {
    let n = grad_norm(grads);
    if n > max_norm as f64 && n > 0.0 {
        let s = (max_norm as f64 / n) as f32;
        for (w, b) in &mut grads.layers {
            for g in w.iter_mut().chain(b.iter_mut()) {
                *g *= s;
            }
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules() {
        assert_eq!(Schedule::Constant.rate(1.0, 50, 10, 100), 1.0);
        let s = Schedule::Step {
            every_epochs: 2,
            gamma: 0.5,
        };
        assert_eq!(s.rate(1.0, 19, 10, 100), 1.0);
        assert_eq!(s.rate(1.0, 20, 10, 100), 0.5);
        let c = Schedule::Cosine { min_factor: 0.1 };
        assert!((c.rate(1.0, 0, 10, 100) - 1.0).abs() < 1e-6);
        assert!((c.rate(1.0, 50, 10, 100) - 0.55).abs() < 1e-6);
        assert!((c.rate(1.0, 100, 10, 100) - 0.1).abs() < 1e-6);
    }
}
