//! RAFT-Stereo's sequence L1 loss.

use burn::tensor::Tensor;

use crate::mask::{sanitized, supervised_mask};
use crate::{DisparityLoss, LossTarget, LossTerms};

/// The per-iteration weights `w_k = gamma^(N-k)`, `k = 1..N`: the last prediction gets 1.
///
/// With `adjust`, `gamma` is first replaced by RAFT-Stereo's `gamma^(15/(N-1))` (so the first
/// prediction's weight does not depend on `N`); for `N = 1` the single weight is 1 either way.
pub fn sequence_weights(count: usize, gamma: f64, adjust: bool) -> Vec<f64> {
    let gamma = if adjust && count > 1 { gamma.powf(15.0 / (count as f64 - 1.0)) } else { gamma };
    (1..=count).map(|k| gamma.powi((count - k) as i32)).collect()
}

/// `sum_k weights[k] * loss_k` over the predictions.
///
/// # Panics
/// When `predictions` is empty.
pub(crate) fn weighted_sum(
    predictions: &[Tensor<4>],
    weights: &[f64],
    per_prediction: impl Fn(&Tensor<4>) -> Tensor<1>,
) -> Tensor<1> {
    assert!(!predictions.is_empty(), "a disparity loss needs at least one prediction");
    predictions
        .iter()
        .zip(weights)
        .map(|(prediction, &weight)| per_prediction(prediction).mul_scalar(weight))
        .reduce(|total, term| total + term)
        .expect("at least one prediction")
}

/// RAFT-Stereo's loss: `sum_k gamma'^(N-k) * mean_{supervised} |D_k - D_gt|` with
/// `gamma' = gamma^(15/(N-1))`, the mean over the supervised pixels of the whole batch
/// (`valid >= 0.5`, `|D_gt| < max_disparity`) and `D_gt` the bilinear ground truth.
/// A batch without supervised pixels gives 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SequenceL1Loss {
    /// Base decay, adjusted to the iteration count.
    pub gamma: f64,
    /// Ground truth at or above this is not supervised.
    pub max_disparity: f64,
}

impl DisparityLoss for SequenceL1Loss {
    /// # Shapes
    /// - `predictions`: each `[N, 1, H, W]`
    /// - output: `[1]`
    ///
    /// # Panics
    /// When `predictions` is empty.
    fn loss(&self, predictions: &[Tensor<4>], target: &LossTarget) -> Tensor<1> {
        let gt = target.disparity_bilinear.clone();
        let supervised = supervised_mask(gt.clone(), target.valid.clone(), self.max_disparity);
        let gt = sanitized(gt, supervised.clone());
        let supervised = supervised.float();
        let count = supervised.clone().sum().clamp_min(1.0);
        let weights = sequence_weights(predictions.len(), self.gamma, true);
        weighted_sum(predictions, &weights, |prediction| {
            ((prediction.clone() - gt.clone()).abs() * supervised.clone()).sum() / count.clone()
        })
    }

    /// The sum over the supervised pixels and their count.
    fn terms(&self, predictions: &[Tensor<4>], target: &LossTarget) -> LossTerms {
        let gt = target.disparity_bilinear.clone();
        let supervised = supervised_mask(gt.clone(), target.valid.clone(), self.max_disparity);
        let gt = sanitized(gt, supervised.clone());
        let supervised = supervised.float();
        let count = f64::from(dgstereo_core::tensor::to_vec(supervised.clone().sum())[0]);
        let weights = sequence_weights(predictions.len(), self.gamma, true);
        let sum = weighted_sum(predictions, &weights, |prediction| {
            ((prediction.clone() - gt.clone()).abs() * supervised.clone()).sum()
        });
        LossTerms { sum, count }
    }
}
