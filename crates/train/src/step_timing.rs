//! What the parts of a training step took, and random pairs to time steps on.

use burn::tensor::{Device, Tensor};
use dgstereo_core::random_values::RandomValues;
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
///
/// The values come from a generator of their own ([`RandomValues`], seed 0), not from the
/// backend's process-wide one: a draw from that generator while another thread initialises a
/// seeded run would change that run's initial weights.
pub fn random_batch(n: usize, [h, w]: [usize; 2], max_disparity: f32, device: &Device) -> TensorBatch {
    let mut random = RandomValues::new(0);
    let left = random.uniform([n, 3, h, w], [0.0, 255.0], device);
    let right = random.uniform([n, 3, h, w], [0.0, 255.0], device);
    let disparity = random.uniform([n, 1, h, w], [0.0, max_disparity], device);
    TensorBatch {
        left,
        right,
        target: LossTarget {
            disparity_bilinear: disparity.clone(),
            disparity_nearest: disparity,
            valid: Tensor::ones([n, 1, h, w], device),
        },
        names: (0..n).map(|i| format!("random-{i}")).collect(),
    }
}
