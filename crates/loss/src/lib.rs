//! Losses over the sequence of disparity predictions.
//!
//! RAFT-Stereo supervises every iteration's prediction with an exponentially growing weight.
//! The [`DisparityLoss`] trait takes all predictions and a [`LossTarget`]; implementations
//! differ in which pixels are supervised and how the per-iteration terms are normalised:
//!
//! - `sequence-l1` ([`SequenceL1Loss`]): RAFT-Stereo's loss, mean L1 over the valid pixels,
//!   weights `gamma'^(N-k)` with `gamma' = gamma^(15/(N-1))`, or with `gamma_adjustment =
//!   "defom-stereo"` DEFOM-Stereo's `gamma'^(N-k+1)` with `gamma' = gamma^(15/N)`
//!   ([`GammaAdjustment`]); with `initial_disparity = "smooth-l1"` IGEV-Stereo's, which adds the
//!   smooth-L1 mean of the network's initial disparity ([`InitialDisparityTerm`]);
//! - `edge-aware` ([`EdgeAwareLoss`]): the paper's EALS, which additionally drops pixels where the
//!   bilinearly and nearest-resized ground truths disagree by more than `tau` ([`edge_mask`]),
//!   normalises each term by the full pixel count and weights it `gamma^(N-k)`.
//!
//! A loss reads [`Predictions`]: every iteration's disparity and, from a network that has one
//! (IGEV-Stereo), the initial disparity at full resolution. A slice of disparities converts into
//! predictions without an initial one.
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
//! # initial_disparity = "smooth-l1"      # sequence-l1 only; "none" by default
//! gamma = 0.9
//! max_disparity = 700.0
//! ```
//!
//! Design decision: the stage's contract is the trait [`DisparityLoss`]: each loss implements it,
//! [`LossConfig`] delegates to its kind with one `match` per method, and `tests/stage_contract.rs`
//! runs every loss through one body generic over the trait.
#![deny(missing_docs)]

pub mod edge_aware;
pub mod initial;
pub mod mask;
pub mod sequence;

pub use edge_aware::EdgeAwareLoss;
pub use initial::{InitialDisparityTerm, smooth_l1};
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

/// What a network predicted, as a loss reads it.
///
/// # Shapes
/// All `[N, 1, H, W]`, the ground truth's: positive disparity.
#[derive(Debug, Clone, Copy)]
pub struct Predictions<'a> {
    /// The disparity after each iteration, first first.
    pub iterations: &'a [Tensor<4>],
    /// The disparity the loop started from, upsampled to full resolution by the network itself
    /// (IGEV-Stereo's soft-argmin start); `None` from a network without one.
    pub initial: Option<&'a Tensor<4>>,
}

impl<'a> From<&'a [Tensor<4>]> for Predictions<'a> {
    /// The iterations' disparities without an initial one.
    fn from(iterations: &'a [Tensor<4>]) -> Self {
        Self { iterations, initial: None }
    }
}

impl<'a> From<&'a Vec<Tensor<4>>> for Predictions<'a> {
    /// The iterations' disparities without an initial one.
    fn from(iterations: &'a Vec<Tensor<4>>) -> Self {
        Self { iterations, initial: None }
    }
}

impl<'a, const N: usize> From<&'a [Tensor<4>; N]> for Predictions<'a> {
    /// The iterations' disparities without an initial one.
    fn from(iterations: &'a [Tensor<4>; N]) -> Self {
        Self { iterations, initial: None }
    }
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
/// prediction's shape is not the ground truth's ([`check_inputs`]), and with
/// [`dgstereo_core::Error::Config`] when the loss supervises an initial disparity the
/// predictions lack ([`InitialDisparityTerm::input`]).
pub trait DisparityLoss {
    /// The scalar loss of `predictions` ([`Predictions`], or a slice of one `[N, 1, H, W]`
    /// positive disparity per iteration).
    fn loss<'a>(
        &self,
        predictions: impl Into<Predictions<'a>>,
        target: &LossTarget,
    ) -> dgstereo_core::Result<Tensor<1>>;

    /// The same loss as [`LossTerms`]: `loss` equals `sum / max(count, 1)` up to rounding.
    fn terms<'a>(
        &self,
        predictions: impl Into<Predictions<'a>>,
        target: &LossTarget,
    ) -> dgstereo_core::Result<LossTerms>;
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
        /// Whether the network's initial disparity is supervised too: not at all (default) or
        /// IGEV-Stereo's smooth-L1 term.
        #[serde(default)]
        initial_disparity: InitialDisparityTerm,
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
/// IGEV-Stereo's largest supervised disparity (`--max_disp`).
pub const IGEV_MAX_DISPARITY: f64 = 192.0;

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
            initial_disparity: InitialDisparityTerm::None,
        }
    }
}

impl LossConfig {
    /// EALS with the paper's defaults (`tau = 0.9`, `gamma = 0.9`, `max_disparity = 700`).
    pub fn edge_aware() -> Self {
        Self::EdgeAware { tau: DEFAULT_TAU, gamma: DEFAULT_GAMMA, max_disparity: DEFAULT_MAX_DISPARITY }
    }

    /// IGEV-Stereo's `sequence_loss` (`train_stereo.py`): RAFT-Stereo's weights with `gamma =
    /// 0.9`, ground truth at or above `max_disp` = 192 unsupervised, and the smooth-L1 term of the
    /// initial disparity.
    pub fn igev_stereo() -> Self {
        Self::SequenceL1 {
            gamma: DEFAULT_GAMMA,
            max_disparity: IGEV_MAX_DISPARITY,
            gamma_adjustment: GammaAdjustment::RaftStereo,
            initial_disparity: InitialDisparityTerm::SmoothL1,
        }
    }

    /// Whether the loss reads [`Predictions::initial`], the network's initial disparity.
    pub fn needs_initial_disparity(&self) -> bool {
        matches!(self, Self::SequenceL1 { initial_disparity, .. } if initial_disparity.needs_initial())
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
    fn loss<'a>(
        &self,
        predictions: impl Into<Predictions<'a>>,
        target: &LossTarget,
    ) -> dgstereo_core::Result<Tensor<1>> {
        match *self {
            Self::SequenceL1 { gamma, max_disparity, gamma_adjustment, initial_disparity } => {
                SequenceL1Loss { gamma, max_disparity, adjustment: gamma_adjustment, initial: initial_disparity }
                    .loss(predictions, target)
            }
            Self::EdgeAware { tau, gamma, max_disparity } => {
                EdgeAwareLoss { tau, gamma, max_disparity }.loss(predictions, target)
            }
        }
    }

    fn terms<'a>(
        &self,
        predictions: impl Into<Predictions<'a>>,
        target: &LossTarget,
    ) -> dgstereo_core::Result<LossTerms> {
        match *self {
            Self::SequenceL1 { gamma, max_disparity, gamma_adjustment, initial_disparity } => {
                SequenceL1Loss { gamma, max_disparity, adjustment: gamma_adjustment, initial: initial_disparity }
                    .terms(predictions, target)
            }
            Self::EdgeAware { tau, gamma, max_disparity } => {
                EdgeAwareLoss { tau, gamma, max_disparity }.terms(predictions, target)
            }
        }
    }
}
