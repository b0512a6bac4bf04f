//! EALS, edge-aware loss suppression.

use burn::tensor::Tensor;
use dgstereo_core::Result;

use crate::mask::{edge_mask, sanitized, supervised_mask};
use crate::sequence::{check_inputs, sequence_weights, weighted_sum};
use crate::{DisparityLoss, LossTarget, LossTerms, Predictions};

/// Edge-aware loss suppression (the paper's EALS).
///
/// Resizing the ground truth bilinearly smears depth discontinuities into disparities no surface
/// has; nearest-neighbour resizing does not. EALS supervises the bilinear ground truth only where
/// the two agree to within `tau`:
///
/// ```text
/// M     = |D_bili - D_near| <= tau                       (edge_mask)
/// V     = valid >= 0.5  and  |D_bili| < max_disparity     (supervised_mask)
/// L_k   = sum_{b,y,x} M * V * |D_bili - D_k|  /  (B * H * W)
/// L     = sum_{k=1..N} gamma^(N-k) * L_k
/// ```
///
/// `L_k` divides by every pixel of the batch (`B` images of `H x W`), not by the supervised count:
/// the per-image `sum / (H * W)` of the paper, averaged over the batch's images. `gamma` is used as
/// given (no RAFT-Stereo `15/(N-1)` adjustment), so the last prediction has weight 1. An initial
/// disparity among the predictions is not supervised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeAwareLoss {
    /// Largest `|D_bili - D_near|` still supervised.
    pub tau: f64,
    /// Per-iteration decay.
    pub gamma: f64,
    /// Ground truth at or above this is not supervised.
    pub max_disparity: f64,
}

impl EdgeAwareLoss {
    /// The pixels this loss supervises, as 0/1 floats: `M * V` above.
    ///
    /// # Shapes
    /// - output: `[N, 1, H, W]`
    pub fn mask(&self, target: &LossTarget) -> Tensor<4> {
        let supervised = supervised_mask(target.disparity_bilinear.clone(), target.valid.clone(), self.max_disparity);
        let edges = edge_mask(target.disparity_bilinear.clone(), target.disparity_nearest.clone(), self.tau);
        supervised.float() * edges
    }
}

impl DisparityLoss for EdgeAwareLoss {
    /// # Shapes
    /// - `predictions`: each `[N, 1, H, W]`
    /// - output: `[1]`
    fn loss<'a>(&self, predictions: impl Into<Predictions<'a>>, target: &LossTarget) -> Result<Tensor<1>> {
        let predictions: Predictions<'_> = predictions.into();
        let predictions = predictions.iterations;
        check_inputs(predictions, target)?;
        let mask = self.mask(target);
        let gt = sanitized(target.disparity_bilinear.clone(), mask.clone().greater_elem(0.5));
        let weights = sequence_weights(predictions.len(), self.gamma, false);
        weighted_sum(predictions, &weights, |prediction| {
            ((prediction.clone() - gt.clone()).abs() * mask.clone()).mean()
        })
    }

    /// The sum over the supervised pixels and the count of all pixels (`B * H * W`).
    fn terms<'a>(&self, predictions: impl Into<Predictions<'a>>, target: &LossTarget) -> Result<LossTerms> {
        let predictions: Predictions<'_> = predictions.into();
        let predictions = predictions.iterations;
        check_inputs(predictions, target)?;
        let mask = self.mask(target);
        let gt = sanitized(target.disparity_bilinear.clone(), mask.clone().greater_elem(0.5));
        let weights = sequence_weights(predictions.len(), self.gamma, false);
        let count = mask.dims().iter().product::<usize>() as f64;
        let sum = weighted_sum(predictions, &weights, |prediction| {
            ((prediction.clone() - gt.clone()).abs() * mask.clone()).sum()
        })?;
        Ok(LossTerms { sum, count })
    }
}
