//! RAFT-Stereo's sequence L1 loss.

use burn::tensor::Tensor;
use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::initial::{InitialDisparityTerm, smooth_l1};
use crate::mask::{sanitized, supervised_mask};
use crate::{DisparityLoss, LossTarget, LossTerms, Predictions};

/// The per-iteration weights `w_k = gamma^(N-k)`, `k = 1..N`: the last prediction gets 1.
///
/// With `adjust`, `gamma` is first replaced by RAFT-Stereo's `gamma^(15/(N-1))` (so the first
/// prediction's weight does not depend on `N`); for `N = 1` the single weight is 1 either way.
pub fn sequence_weights(count: usize, gamma: f64, adjust: bool) -> Vec<f64> {
    let gamma = if adjust && count > 1 { gamma.powf(15.0 / (count as f64 - 1.0)) } else { gamma };
    (1..=count).map(|k| gamma.powi((count - k) as i32)).collect()
}

/// How the sequence loss's decay follows the number of predictions `N` (`gamma_adjustment`).
///
/// The two official training scripts write the "adjusted gamma" differently; each weighting is
/// its script's `sequence_loss` term by term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GammaAdjustment {
    /// RAFT-Stereo's `train_stereo.py`: `gamma' = gamma^(15/(N-1))`, weights `gamma'^(N-k)`
    /// for `k = 1..N`, the last prediction 1 and the first `gamma^15` ([`sequence_weights`]).
    #[default]
    RaftStereo,
    /// DEFOM-Stereo's `utils/utils.py`: `gamma' = gamma^(15/N)`, weights `gamma'^(N-k+1)`, so
    /// the last prediction weighs `gamma'` and the first `gamma^15`; every prediction of the
    /// loop counts, the scale iterations first.
    DefomStereo,
}

impl GammaAdjustment {
    /// Both adjustments, in the order of the enum.
    pub const ALL: [Self; 2] = [Self::RaftStereo, Self::DefomStereo];

    /// The name the TOML key `gamma_adjustment` writes.
    pub fn name(self) -> &'static str {
        match self {
            Self::RaftStereo => "raft-stereo",
            Self::DefomStereo => "defom-stereo",
        }
    }

    /// The per-prediction weights of `count` predictions with base decay `gamma`, first
    /// prediction first.
    pub fn weights(self, count: usize, gamma: f64) -> Vec<f64> {
        match self {
            Self::RaftStereo => sequence_weights(count, gamma, true),
            Self::DefomStereo => {
                let adjusted = gamma.powf(15.0 / count as f64);
                (1..=count).map(|k| adjusted.powi((count - k + 1) as i32)).collect()
            }
        }
    }
}

/// Checks what a loss reads: at least one prediction, each of the target's `[N, 1, H, W]`
/// shape, and the target's three maps of one shape.
///
/// # Errors
/// [`Error::Shape`] naming the shapes that differ.
pub fn check_inputs(predictions: &[Tensor<4>], target: &LossTarget) -> Result<()> {
    let dims = target.disparity_bilinear.dims();
    if target.disparity_nearest.dims() != dims || target.valid.dims() != dims {
        return Err(Error::Shape(format!(
            "loss target: the bilinear ground truth is {dims:?}, the nearest {:?} and the validity mask {:?}",
            target.disparity_nearest.dims(),
            target.valid.dims()
        )));
    }
    if dims[1] != 1 {
        return Err(Error::Shape(format!("loss target: expected [N, 1, H, W] disparity, got {dims:?}")));
    }
    if predictions.is_empty() {
        return Err(Error::Shape("a disparity loss needs at least one prediction, got none".into()));
    }
    if let Some((k, p)) = predictions.iter().enumerate().find(|(_, p)| p.dims() != dims) {
        return Err(Error::Shape(format!("loss: prediction {k} is {:?} but the ground truth is {dims:?}", p.dims())));
    }
    Ok(())
}

/// `sum_k weights[k] * loss_k` over the predictions (checked by [`check_inputs`] first).
pub(crate) fn weighted_sum(
    predictions: &[Tensor<4>],
    weights: &[f64],
    per_prediction: impl Fn(&Tensor<4>) -> Tensor<1>,
) -> Result<Tensor<1>> {
    predictions
        .iter()
        .zip(weights)
        .map(|(prediction, &weight)| per_prediction(prediction).mul_scalar(weight))
        .reduce(|total, term| total + term)
        .ok_or_else(|| Error::Shape("a disparity loss needs at least one prediction, got none".into()))
}

/// RAFT-Stereo's loss: `sum_k w_k * mean_{supervised} |D_k - D_gt|` with the weights of its
/// [`GammaAdjustment`] (RAFT-Stereo's `gamma'^(N-k)`, `gamma' = gamma^(15/(N-1))`, or
/// DEFOM-Stereo's), the mean over the supervised pixels of the whole batch
/// (`valid >= 0.5`, `|D_gt| < max_disparity`) and `D_gt` the bilinear ground truth; with
/// [`InitialDisparityTerm::SmoothL1`] IGEV-Stereo's, plus `mean_{supervised} smooth_l1(D_0 - D_gt)`
/// of the initial disparity `D_0`. A batch without supervised pixels gives 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SequenceL1Loss {
    /// Base decay, adjusted to the iteration count.
    pub gamma: f64,
    /// Ground truth at or above this is not supervised.
    pub max_disparity: f64,
    /// How `gamma` is adjusted to the number of predictions.
    pub adjustment: GammaAdjustment,
    /// Whether the initial disparity is supervised too.
    pub initial: InitialDisparityTerm,
}

impl SequenceL1Loss {
    /// The ground truth with unsupervised pixels zeroed and the 0/1 map of the supervised
    /// pixels (`valid >= 0.5`, `|D_gt| < max_disparity`), both `[N, 1, H, W]`.
    fn supervision(&self, target: &LossTarget) -> (Tensor<4>, Tensor<4>) {
        let gt = target.disparity_bilinear.clone();
        let supervised = supervised_mask(gt.clone(), target.valid.clone(), self.max_disparity);
        (sanitized(gt, supervised.clone()), supervised.float())
    }

    /// `initial_term + sum_k w_k * term(D_k)`, where `term` turns a per-pixel error map into
    /// the value this form adds up (a sum, or a sum over the count), for predictions that passed
    /// [`check_inputs`]; the initial disparity is checked here ([`InitialDisparityTerm::input`]).
    fn combined(
        &self,
        predictions: Predictions<'_>,
        target: &LossTarget,
        term: impl Fn(Tensor<4>, &Tensor<4>) -> Tensor<1>,
    ) -> Result<Tensor<1>> {
        let initial = self.initial.input(predictions.initial, target.disparity_bilinear.dims())?;
        let (gt, supervised) = self.supervision(target);
        let weights = self.adjustment.weights(predictions.iterations.len(), self.gamma);
        let sequence = weighted_sum(predictions.iterations, &weights, |prediction| {
            term((prediction.clone() - gt.clone()).abs(), &supervised)
        })?;
        Ok(match initial {
            // IGEV-Stereo's: the initial disparity's term plus the iterations'.
            Some(initial) => term(smooth_l1(initial.clone() - gt), &supervised) + sequence,
            None => sequence,
        })
    }
}

impl DisparityLoss for SequenceL1Loss {
    /// # Shapes
    /// - `predictions`: each `[N, 1, H, W]`
    /// - output: `[1]`
    fn loss<'a>(&self, predictions: impl Into<Predictions<'a>>, target: &LossTarget) -> Result<Tensor<1>> {
        let predictions: Predictions<'_> = predictions.into();
        check_inputs(predictions.iterations, target)?;
        let count = self.supervision(target).1.sum().clamp_min(1.0);
        self.combined(predictions, target, |error, supervised| (error * supervised.clone()).sum() / count.clone())
    }

    /// The sum over the supervised pixels and their count.
    fn terms<'a>(&self, predictions: impl Into<Predictions<'a>>, target: &LossTarget) -> Result<LossTerms> {
        let predictions: Predictions<'_> = predictions.into();
        check_inputs(predictions.iterations, target)?;
        let sum = self.combined(predictions, target, |error, supervised| (error * supervised.clone()).sum())?;
        let count = f64::from(dgstereo_core::tensor::to_vec(self.supervision(target).1.sum())[0]);
        Ok(LossTerms { sum, count })
    }
}
