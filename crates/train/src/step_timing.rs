//! What the parts of a training step took, and random pairs to time steps on.

use burn::tensor::{Device, Distribution, Tensor};
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
    /// Summing the gradients over the ranks of a data-parallel run (0 in one process).
    pub all_reduce: f64,
    /// Clipping, the optimiser's update and the moving average.
    pub optimizer: f64,
}

impl StepSeconds {
    /// The whole step.
    pub fn total(&self) -> f64 {
        self.forward + self.backward + self.all_reduce + self.optimizer
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
