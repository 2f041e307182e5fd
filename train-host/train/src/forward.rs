//! Any network's batched forward and backward, by its [`ModelKind`]:
//! PCRNet and i-PCRNet ([`crate::model`]) or PointNetLK ([`crate::lk`]).
//! What the trainer and its validation call.

use crate::F32Params;
use crate::lk;
use crate::loss::LossKind;
use crate::model::{self, Batch, ModelKind, RigidPose, StepOutput};

/// Estimated poses (source onto template) of `b` pairs of `n` points, no
/// gradient.
pub fn predict(
    params: &F32Params,
    kind: ModelKind,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    b: usize,
    n: usize,
) -> Vec<RigidPose> {
    match kind {
        ModelKind::Pcrnet | ModelKind::Ipcrnet { .. } => {
            model::predict(params, kind.iterations(), template, source, b, n)
        }
        ModelKind::PointNetLk { iterations } => {
            lk::predict(params, iterations, template, source, b, n)
        }
    }
}

/// Forward and backward of one batch: the mean loss over the pairs, its
/// gradient and the estimated poses.
pub fn loss_and_grad(
    params: &F32Params,
    kind: ModelKind,
    loss: LossKind,
    batch: &Batch,
) -> StepOutput {
    match kind {
        ModelKind::Pcrnet | ModelKind::Ipcrnet { .. } => {
            model::loss_and_grad(params, kind.iterations(), loss, batch)
        }
        ModelKind::PointNetLk { iterations } => lk::loss_and_grad(params, iterations, loss, batch),
    }
}
