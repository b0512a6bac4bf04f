//! Losses over the sequence of disparity predictions.
//!
//! RAFT-Stereo supervises every iteration's prediction with an exponentially growing weight.
//! The [`DisparityLoss`] trait takes all predictions and a [`LossTarget`]; implementations
//! differ in which pixels are supervised and how the per-iteration terms are normalised:
//!
//! - `sequence-l1` ([`SequenceL1Loss`]): RAFT-Stereo's loss, mean L1 over the valid pixels,
//!   weights `gamma'^(N-k)` with `gamma' = gamma^(15/(N-1))`, or with `gamma_adjustment =
//!   "defom-stereo"` DEFOM-Stereo's `gamma'^(N-k+1)` with `gamma' = gamma^(15/N)`
//!   ([`GammaAdjustment`]);
//! - `edge-aware` ([`EdgeAwareLoss`]): the paper's EALS, which additionally drops pixels where the
//!   bilinearly and nearest-resized ground truths disagree by more than `tau` ([`edge_mask`]),
//!   normalises each term by the full pixel count and weights it `gamma^(N-k)`.
//!
//! In both, ground truth that is invalid (`valid < 0.5`), at or above `max_disparity` in
//! magnitude, or not finite is excluded, and cannot leak NaN into the loss or its gradient.
//!
//! # Config (TOML)
//! ```toml
//! [loss]
//! kind = "edge-aware"      # or "sequence-l1" (default)
//! tau = 0.9                # edge-aware only
//! # gamma_adjustment = "defom-stereo"   # sequence-l1 only; "raft-stereo" by default
//! gamma = 0.9
//! max_disparity = 700.0
//! ```
//!
//! Design decision: the stage's contract is the trait [`DisparityLoss`]: each loss implements it,
//! [`LossConfig`] delegates to its kind with one `match` per method, and `tests/stage_contract.rs`
//! runs every loss through one body generic over the trait.
#![deny(missing_docs)]

pub mod edge_aware;
pub mod mask;
pub mod sequence;

pub use edge_aware::EdgeAwareLoss;
pub use mask::{edge_mask, supervised_mask};
pub use sequence::{GammaAdjustment, SequenceL1Loss, check_inputs, sequence_weights};

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

/// The ground truth a loss sees.
///
/// # Shapes
/// All `[N, 1, H, W]`: positive disparity resized bilinearly and by nearest neighbour (equal when
/// no resize happened), and the validity mask (1 = valid).
#[derive(Debug, Clone)]
pub struct LossTarget {
    /// Ground truth resized bilinearly.
    pub disparity_bilinear: Tensor<4>,
    /// Ground truth resized by nearest neighbour.
    pub disparity_nearest: Tensor<4>,
    /// 1 where the ground truth is valid.
    pub valid: Tensor<4>,
}

/// A loss split into a sum and the count it is divided by, both additive over the batch's
/// images.
///
/// The loss of a batch is `sum / max(count, 1)`. Split a batch into shards (the ranks of a
/// data-parallel run), and the whole batch's loss is the shards' sums added, over their counts
/// added: each shard can then take the gradient of `sum / total count` alone, and the gradients
/// added over the shards are the whole batch's.
#[derive(Debug, Clone)]
pub struct LossTerms {
    /// The weighted sum over the predictions and pixels, `[1]`.
    pub sum: Tensor<1>,
    /// What the sum is divided by (supervised pixels, or all pixels).
    pub count: f64,
}

/// The stage trait.
///
/// Both methods fail with [`dgstereo_core::Error::Shape`] when there is no prediction or a
/// prediction's shape is not the ground truth's ([`check_inputs`]).
pub trait DisparityLoss {
    /// The scalar loss of `predictions` (one `[N, 1, H, W]` positive disparity per iteration).
    fn loss(&self, predictions: &[Tensor<4>], target: &LossTarget) -> dgstereo_core::Result<Tensor<1>>;

    /// The same loss as [`LossTerms`]: `loss` equals `sum / max(count, 1)` up to rounding.
    fn terms(&self, predictions: &[Tensor<4>], target: &LossTarget) -> dgstereo_core::Result<LossTerms>;
}

/// Which loss an experiment uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum LossConfig {
    /// RAFT-Stereo's sequence L1 loss ([`SequenceL1Loss`]).
    SequenceL1 {
        /// Base decay; adjusted to the iteration count as `gamma^(15/(N-1))`.
        #[serde(default = "default_gamma")]
        gamma: f64,
        /// Pixels with |disparity| at or above this are excluded.
        #[serde(default = "default_max_disparity")]
        max_disparity: f64,
        /// How `gamma` follows the number of predictions: RAFT-Stereo's (default) or
        /// DEFOM-Stereo's.
        #[serde(default)]
        gamma_adjustment: GammaAdjustment,
    },
    /// Edge-aware loss suppression ([`EdgeAwareLoss`]).
    EdgeAware {
        /// Pixels where bilinear and nearest ground truth differ by more than this are excluded.
        #[serde(default = "default_tau")]
        tau: f64,
        /// Per-iteration decay, used as given: weight `gamma^(N-k)`.
        #[serde(default = "default_gamma")]
        gamma: f64,
        /// Pixels with |disparity| at or above this are excluded.
        #[serde(default = "default_max_disparity")]
        max_disparity: f64,
    },
}

/// Default decay of both losses.
pub const DEFAULT_GAMMA: f64 = 0.9;
/// Default largest supervised disparity.
pub const DEFAULT_MAX_DISPARITY: f64 = 700.0;
/// Default EALS threshold.
pub const DEFAULT_TAU: f64 = 0.9;

fn default_gamma() -> f64 {
    DEFAULT_GAMMA
}
fn default_max_disparity() -> f64 {
    DEFAULT_MAX_DISPARITY
}
fn default_tau() -> f64 {
    DEFAULT_TAU
}

impl Default for LossConfig {
    fn default() -> Self {
        Self::SequenceL1 {
            gamma: DEFAULT_GAMMA,
            max_disparity: DEFAULT_MAX_DISPARITY,
            gamma_adjustment: GammaAdjustment::RaftStereo,
        }
    }
}

impl LossConfig {
    /// EALS with the paper's defaults (`tau = 0.9`, `gamma = 0.9`, `max_disparity = 700`).
    pub fn edge_aware() -> Self {
        Self::EdgeAware { tau: DEFAULT_TAU, gamma: DEFAULT_GAMMA, max_disparity: DEFAULT_MAX_DISPARITY }
    }

    /// Whether the loss reads [`LossTarget::disparity_nearest`] (the data pipeline may then skip
    /// the nearest resize and pass the bilinear ground truth twice).
    pub fn needs_nearest(&self) -> bool {
        matches!(self, Self::EdgeAware { .. })
    }

    /// One configuration of every kind, with the defaults, in the order of the enum; tests draw
    /// the kinds from here (`every_kind_is_listed` fails when a kind is missing).
    pub fn variants() -> Vec<Self> {
        vec![Self::default(), Self::edge_aware()]
    }

    /// The kind's name as the TOML key `kind` writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::SequenceL1 { .. } => "sequence-l1",
            Self::EdgeAware { .. } => "edge-aware",
        }
    }

    /// Everything wrong with the values, keys relative to the loss table: `tau` finite and
    /// `>= 0`, `gamma` in `(0, 1]`, `max_disparity` finite and `> 0`.
    pub fn problems(&self) -> Vec<dgstereo_core::Problem> {
        let mut problems = Vec::new();
        let mut add = |key: &str, reason: String| problems.push(dgstereo_core::Problem::new(key, reason));
        let (gamma, max_disparity) = match *self {
            Self::SequenceL1 { gamma, max_disparity, .. } => (gamma, max_disparity),
            Self::EdgeAware { tau, gamma, max_disparity } => {
                if !(tau.is_finite() && tau >= 0.0) {
                    add("tau", format!("{tau} must be a finite value >= 0"));
                }
                (gamma, max_disparity)
            }
        };
        if !(gamma > 0.0 && gamma <= 1.0) {
            add("gamma", format!("{gamma} must lie in (0, 1]"));
        }
        if !(max_disparity.is_finite() && max_disparity > 0.0) {
            add("max_disparity", format!("{max_disparity} must be a finite value > 0"));
        }
        problems
    }

    /// Checks the values.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] with the first of [`problems`](Self::problems).
    pub fn validate(&self) -> dgstereo_core::Result<()> {
        dgstereo_core::Problem::first(self.problems())
    }
}

impl DisparityLoss for LossConfig {
    fn loss(&self, predictions: &[Tensor<4>], target: &LossTarget) -> dgstereo_core::Result<Tensor<1>> {
        match *self {
            Self::SequenceL1 { gamma, max_disparity, gamma_adjustment } => {
                SequenceL1Loss { gamma, max_disparity, adjustment: gamma_adjustment }.loss(predictions, target)
            }
            Self::EdgeAware { tau, gamma, max_disparity } => {
                EdgeAwareLoss { tau, gamma, max_disparity }.loss(predictions, target)
            }
        }
    }

    fn terms(&self, predictions: &[Tensor<4>], target: &LossTarget) -> dgstereo_core::Result<LossTerms> {
        match *self {
            Self::SequenceL1 { gamma, max_disparity, gamma_adjustment } => {
                SequenceL1Loss { gamma, max_disparity, adjustment: gamma_adjustment }.terms(predictions, target)
            }
            Self::EdgeAware { tau, gamma, max_disparity } => {
                EdgeAwareLoss { tau, gamma, max_disparity }.terms(predictions, target)
            }
        }
    }
}
