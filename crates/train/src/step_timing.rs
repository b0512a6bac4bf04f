//! What the parts of a training step took, and random pairs to time steps on.

use burn::tensor::{Device, Distribution, Tensor};
use dgstereo_core::{DepthPrior, InputPadder};
use dgstereo_loss::LossTarget;
pub use dgstereo_model::stage_backward::{StageBackward, profile_backward};

use crate::batch::TensorBatch;

/// Wall-clock seconds of one step's parts ([`crate::Trainer::step_on`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepSeconds {
    /// The forward pass, the loss and the batch's metrics.
    pub forward: f64,
    /// `loss.backward()` and collecting the parameters' gradients.
    pub backward: f64,
    /// Clipping, the optimiser's update and the moving average.
    pub optimizer: f64,
}

impl StepSeconds {
    /// The whole step.
    pub fn total(&self) -> f64 {
        self.forward + self.backward + self.optimizer
    }
}

/// A batch of `n` random `h x w` pairs (values 0..255) with random ground truth in `0..max
/// disparity`, every pixel valid, on `device` (the trainer's autodiff device): what a step
/// costs does not depend on the values.
pub fn random_batch(n: usize, [h, w]: [usize; 2], max_disparity: f32, device: &Device) -> TensorBatch {
    let image = || Tensor::<4>::random([n, 3, h, w], Distribution::Uniform(0.0, 255.0), device);
    let disparity = Tensor::<4>::random([n, 1, h, w], Distribution::Uniform(0.0, max_disparity as f64), device);
    TensorBatch {
        left: image(),
        right: image(),
        target: LossTarget {
            disparity_bilinear: disparity.clone(),
            disparity_nearest: disparity,
            valid: Tensor::ones([n, 1, h, w], device),
        },
        names: (0..n).map(|i| format!("random-{i}")).collect(),
    }
}

impl crate::Trainer {
    /// Each stage's forward and backward seconds on `batch`, run alone with the step's prior and
    /// iterations ([`profile_backward`]; `dgstereo bench --train --stages`).
    pub fn stage_backward_seconds(&self, batch: &TensorBatch) -> dgstereo_core::Result<Vec<StageBackward>> {
        let prior = crate::trainer::batch_prior(self.prior(), self.parts.model.needs_prior(), batch)?;
        let [_, _, h, w] = batch.left.dims();
        let padder = InputPadder::new(h, w, self.parts.model.pad_divisor());
        let prior = prior.map(|p| DepthPrior { left: padder.pad(p.left), right: padder.pad(p.right) });
        let (left, right) = (padder.pad(batch.left.clone()), padder.pad(batch.right.clone()));
        Ok(profile_backward(&self.model, left, right, prior.as_ref(), self.parts.train.iters))
    }
}
