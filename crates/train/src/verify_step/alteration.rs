//! Deliberate deviations from the reference's recipe, to show that the verification detects each.
//!
//! Three are configuration values of the run; the fourth wraps the recipe's AdamW, since burn's
//! has no switch for its bias correction.

use burn::optim::{AdamW, AdamWState, AdaptiveMomentumState, LearningRate, ModuleOptimizer, Optimizer};
use burn::tensor::{Device, Tensor};
use dgstereo_experiment::TrainingConfig;
use dgstereo_loss::LossConfig;

use crate::trainer::{TrainParts, adamw, adamw_config};

/// One deliberate deviation of the verified run from the recipe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Alteration {
    /// The sequence loss weights its terms `gamma^(N-k)` instead of `gamma'^(N-k)` with
    /// `gamma' = gamma^(15/(N-1))`: `loss.gamma` becomes `gamma^((N-1)/15)`, whose adjusted value
    /// is the plain `gamma`.
    UnadjustedGamma,
    /// No gradient clipping: `train.clip = 0`.
    NoClip,
    /// AdamW without bias correction: `p <- p - lr * m / (sqrt(v) + eps)` with the raw moments.
    NoBiasCorrection,
    /// No warm-up: `train.warmup_fraction = 1 / total_steps`, so the warm-up ends at step 0 and
    /// the first step runs at the peak learning rate.
    NoWarmup,
}

impl Alteration {
    /// Every alteration.
    pub const ALL: [Self; 4] = [Self::UnadjustedGamma, Self::NoClip, Self::NoBiasCorrection, Self::NoWarmup];

    /// Applies the configuration part of the alteration to `parts` (a run of `iters`
    /// iterations); [`Alteration::NoBiasCorrection`] changes the optimiser instead
    /// ([`optimizer`]).
    pub fn apply(self, parts: &mut TrainParts) {
        let train = &mut parts.train;
        match self {
            Self::UnadjustedGamma => {
                if let LossConfig::SequenceL1 { gamma, .. } = &mut parts.loss
                    && train.iters > 1
                {
                    *gamma = gamma.powf((train.iters as f64 - 1.0) / 15.0);
                }
            }
            Self::NoClip => train.clip = 0.0,
            Self::NoBiasCorrection => {}
            Self::NoWarmup => train.warmup_fraction = 1.0 / train.schedule_total_steps() as f64,
        }
    }
}

/// The optimiser of a verified run: the recipe's AdamW ([`adamw`]), or with
/// [`Alteration::NoBiasCorrection`] the same without bias correction.
pub fn optimizer(train: &TrainingConfig, alteration: Option<Alteration>) -> ModuleOptimizer {
    match alteration {
        Some(Alteration::NoBiasCorrection) => ModuleOptimizer::from(Uncorrected(adamw_config(train).build())),
        _ => adamw(train),
    }
}

/// A step count at which `beta^t` is 0 in float32 for any `beta < 0.9999`, so that burn's
/// corrections `1 - beta^t` are exactly 1.
const UNCORRECTED_TIME: usize = 1 << 20;

/// burn's AdamW whose moments start from zero at step [`UNCORRECTED_TIME`]: the moments are
/// those of a fresh optimiser, their bias corrections 1.
#[derive(Clone)]
struct Uncorrected(AdamW);

impl Optimizer for Uncorrected {
    type State<const D: usize> = AdamWState<D>;

    fn step<const D: usize>(
        &self,
        lr: LearningRate,
        tensor: Tensor<D>,
        grad: Tensor<D>,
        state: Option<Self::State<D>>,
    ) -> (Tensor<D>, Option<Self::State<D>>) {
        let state = state.unwrap_or_else(|| {
            let zeros = grad.zeros_like();
            AdamWState::new(AdaptiveMomentumState::new(UNCORRECTED_TIME, zeros.clone(), zeros))
        });
        self.0.step(lr, tensor, grad, Some(state))
    }

    fn to_device<const D: usize>(state: Self::State<D>, device: &Device) -> Self::State<D> {
        AdamW::to_device(state, device)
    }
}
