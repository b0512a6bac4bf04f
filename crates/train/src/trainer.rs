//! One training step: batch, prior, forward over all iterations, loss, backward, clip, AdamW,
//! and with `train.ema_decay` the update of the weights' moving average ([`crate::ema`]).

use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor};
use dgstereo_collective::SingleProcess;
use dgstereo_core::{DepthPrior, Error, Result};
use dgstereo_data::DisparityMap;
use dgstereo_eval::{MetricSums, ValidOptions, accumulate};
use dgstereo_experiment::{ExperimentConfig, TrainingConfig, TrainingDataConfig};
use dgstereo_loss::LossConfig;
use dgstereo_model::{ModelConfig, RaftStereo, TrainingDisparities};
use dgstereo_prior::{Prior, PriorConfig, PriorInput, PriorProvider};

use crate::batch::{TensorBatch, TrainingData};
use crate::clip::clip_global_norm;
use crate::ema::Ema;
use crate::frozen::freeze;
use crate::params::materialize;
use crate::schedule::OneCycleLr;
use crate::start_weights::load_start_weights;
use crate::step_timing::StepSeconds;

/// Everything a run is made of: the experiment's parts and its resolved text
/// (`From<ExperimentConfig>` splits a resolved experiment into them).
#[derive(Debug, Clone)]
pub struct TrainParts {
    /// Name of the run.
    pub name: String,
    /// The network.
    pub model: ModelConfig,
    /// The prior provider.
    pub prior: PriorConfig,
    /// The loss.
    pub loss: LossConfig,
    /// The recipe.
    pub train: TrainingConfig,
    /// The training and validation data.
    pub data: TrainingDataConfig,
    /// The resolved experiment as TOML, stored in every checkpoint.
    pub resolved_toml: String,
}

impl From<ExperimentConfig> for TrainParts {
    /// The parts of a resolved experiment; `resolved_toml` is its complete TOML
    /// ([`ExperimentConfig::to_toml`]).
    fn from(config: ExperimentConfig) -> Self {
        let resolved_toml = config.to_toml();
        Self {
            name: config.name,
            model: config.model,
            prior: config.prior,
            loss: config.loss,
            train: config.train,
            data: config.data,
            resolved_toml,
        }
    }
}

impl TrainParts {
    /// These parts with the official checkpoints they name (`train.init =
    /// "raftstereo-sceneflow"`, the prior's `weights = "depth-anything-v2-base"`) resolved to
    /// files by `fetcher`, fetched on first use ([`dgstereo_weights`]); `resolved_toml` keeps the
    /// names. The front end does this before it trains; the trainer takes files.
    pub fn with_named_weights(self, fetcher: &dgstereo_weights::Fetcher) -> Result<Self> {
        let init = match self.train.init {
            Some(init) => Some(fetcher.resolve_stereo(&init, "train.init")?),
            None => None,
        };
        let monocular_init = match self.train.monocular_init {
            Some(weights) => Some(fetcher.resolve(&weights, dgstereo_weights::Role::Prior, "train.monocular_init")?),
            None => None,
        };
        let prior = fetcher.resolve_prior(self.prior, "prior.weights")?;
        Ok(Self { prior, train: TrainingConfig { init, monocular_init, ..self.train }, ..self })
    }

    /// Checks that no official checkpoint's name is left unresolved
    /// ([`TrainParts::with_named_weights`]).
    pub fn check_named_weights_resolved(&self) -> Result<()> {
        if let Some(init) = &self.train.init {
            dgstereo_weights::check_resolved(init, "train.init")?;
        }
        if let Some(weights) = &self.train.monocular_init {
            dgstereo_weights::check_resolved(weights, "train.monocular_init")?;
        }
        dgstereo_weights::check_resolved_prior(&self.prior, "prior.weights")
    }

    /// Checks every part; the message names the key.
    pub fn validate(&self) -> Result<()> {
        self.model.validate().map_err(|e| e.within("model"))?;
        self.train.validate()?;
        self.data.validate()?;
        self.model.check_prior(self.prior.gives_prior()).map_err(|e| e.within("model"))
    }
}

/// What one step measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// The index (0-based) of the step just taken; `step + 1` steps are complete.
    pub step: usize,
    /// The loss.
    pub loss: f64,
    /// End-point error of the last iteration on the batch's valid pixels.
    pub epe: f64,
    /// Percentage of valid pixels with error > 3 px.
    pub bad3: f64,
    /// The learning rate used.
    pub lr: f64,
    /// The global gradient norm before clipping.
    pub grad_norm: f64,
}

/// What a step computed before clipping and the update, lent to the observer of
/// [`Trainer::step_on`].
pub struct StepInternals<'a> {
    /// The network the step started from (autodiff device).
    pub model: &'a RaftStereo,
    /// Positive disparity after every iteration, `[N, 1, H, W]` each.
    pub predictions: &'a [Tensor<4>],
    /// The initial disparity the loss read, `[N, 1, H, W]` (IGEV-Stereo's upsampled start);
    /// `None` for a network that gives none.
    pub initial: Option<&'a Tensor<4>>,
    /// The gradients, before clipping.
    pub grads: &'a GradientsParams,
}

/// A run in progress: the network on the autodiff device, the optimiser and the step counter.
///
/// Its public face is what a run does ([`Trainer::step`], [`Trainer::step_on`], the models it
/// ships) and what a caller reads about it; its state is the crate's own (the checkpoint and the
/// run loop read and restore it), so no caller can put a run out of step with its optimiser.
pub struct Trainer {
    /// The run's parts.
    pub(crate) parts: TrainParts,
    /// The network (autodiff device, training mode).
    pub(crate) model: RaftStereo,
    /// AdamW and its per-parameter state.
    pub(crate) optimizer: ModuleOptimizer,
    /// The learning-rate schedule.
    pub(crate) schedule: OneCycleLr,
    /// Steps taken so far (the index of the next step).
    pub(crate) step: usize,
    /// The moving average of the weights, when `train.ema_decay` is set.
    pub(crate) ema: Option<Ema>,
    /// The plain device (validation, data).
    pub(crate) device: Device,
    /// The autodiff device.
    pub(crate) autodiff: Device,
    /// What the user should know about how the trainer was set up (see [`Trainer::notices`]).
    pub(crate) notices: Vec<String>,
    /// What the parts of the last step took.
    pub(crate) last_step_seconds: StepSeconds,
    /// Bytes each rank gave the last step's gradient exchange (0 in one process).
    pub(crate) last_exchange_bytes: usize,
    pub(crate) data: TrainingData,
    pub(crate) prior: Prior,
}

/// What a step that fails says before its cause: the step (1-based) and the weights the run
/// keeps, those of the `step` completed ones.
pub(crate) fn stopping_at(step: usize) -> String {
    format!("step {}: stopping with the weights after {step} completed steps", step + 1)
}

/// The AdamW of a recipe (decoupled weight decay, PyTorch's update).
pub fn adamw(train: &TrainingConfig) -> ModuleOptimizer {
    adamw_config(train).init()
}

/// The settings of the recipe's AdamW, for callers that build the optimiser themselves.
///
/// burn-optim's AdamW computes PyTorch's update: `p <- p * (1 - lr * weight_decay)`, then
/// `p <- p - lr * m_hat / (sqrt(v_hat) + eps)` with both moments bias-corrected
/// (`m_hat = m / (1 - beta1^t)`, `v_hat = v / (1 - beta2^t)`). It forms the corrections in
/// float32, 1.3e-5 relative from PyTorch's float64 ones at `t = 1`, far below what a training
/// step can show.
pub fn adamw_config(train: &TrainingConfig) -> AdamWConfig {
    AdamWConfig::new()
        .with_beta_1(train.betas[0] as f32)
        .with_beta_2(train.betas[1] as f32)
        .with_epsilon(train.eps as f32)
        .with_weight_decay(train.weight_decay as f32)
}

/// A freshly initialised network of `config` on `device`, the backend's generator first seeded
/// with `seed` when given.
///
/// The generator may be process-wide and burn draws parameters lazily, at their first use: every
/// initialisation of this crate seeds and draws all parameters ([`materialize`]) under one lock,
/// so runs started concurrently in one process (tests, ablations) get the same initial weights,
/// and a network built only to receive loaded weights (`seed = None`) does not draw from another
/// run's seeded sequence.
pub fn init_model(config: &ModelConfig, device: &Device, seed: Option<u64>) -> Result<RaftStereo> {
    static INIT: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = INIT.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(seed) = seed {
        device.seed(seed);
    }
    let model = config.init(device)?;
    materialize(&model);
    Ok(model)
}

/// The prior of a batch, or `None` when the model does not use one.
pub fn batch_prior(prior: &Prior, needs: bool, batch: &TensorBatch) -> Result<Option<DepthPrior>> {
    if !needs {
        return Ok(None);
    }
    let input = PriorInput {
        left: batch.left.clone(),
        right: batch.right.clone(),
        gt_disparity: Some(batch.target.disparity_bilinear.clone()),
        names: batch.names.clone(),
    };
    prior.provide(&input)?.map(Some).ok_or_else(|| Error::config("prior.kind", "the provider gave no prior"))
}

/// Runs `model` on a batch of any size and returns positive disparity after every iteration kept
/// ([`dgstereo_model::padded_disparities`] with the configured cost volume).
///
/// # Shapes
/// - `left`, `right`: `[N, 3, H, W]`; prior maps `[N, 1, H, W]`
/// - each output: `[N, 1, H, W]`
pub fn forward_disparities(
    model: &RaftStereo,
    config: &ModelConfig,
    left: Tensor<4>,
    right: Tensor<4>,
    prior: Option<&DepthPrior>,
    iters: usize,
    all_iterations: bool,
) -> Result<Vec<Tensor<4>>> {
    let options = dgstereo_model::ForwardOptions { all_iterations, ..Default::default() };
    dgstereo_model::padded_disparities(model, config, left, right, prior, iters, options)
}

/// Metric sums of a `[N, 1, H, W]` prediction against ground truth and a 0/1 validity map.
pub fn batch_metrics(prediction: Tensor<4>, gt: Tensor<4>, valid: Tensor<4>) -> Result<MetricSums> {
    let [n, _, h, w] = prediction.dims();
    let p = dgstereo_core::tensor::to_vec(prediction);
    let g = dgstereo_core::tensor::to_vec(gt);
    let v = dgstereo_core::tensor::to_vec(valid);
    let mut sums = MetricSums::default();
    for i in 0..n {
        let r = i * h * w..(i + 1) * h * w;
        let gt: Vec<f32> =
            g[r.clone()].iter().zip(&v[r.clone()]).map(|(&d, &m)| if m >= 0.5 { d } else { f32::NAN }).collect();
        let s = accumulate(
            &DisparityMap::from_vec(w, h, p[r].to_vec())?,
            &DisparityMap::from_vec(w, h, gt)?,
            None,
            ValidOptions::default(),
        )?;
        sums.merge(&s);
    }
    Ok(sums)
}

impl Trainer {
    /// A fresh run: weights initialised from `train.seed` on `device`, then those the recipe
    /// names ([`load_start_weights`]: `train.monocular_init`, `train.feature_init`, `train.init`).
    pub fn new(parts: TrainParts, device: &Device) -> Result<Self> {
        parts.validate()?;
        parts.check_named_weights_resolved()?;
        let model = init_model(&parts.model, device, Some(parts.train.seed))?;
        let (model, notices) = load_start_weights(model, &parts.train)?;
        let optimizer = adamw(&parts.train);
        let mut trainer = Self::with_model(parts, model, device, optimizer, 0)?;
        trainer.notices = notices;
        Ok(trainer)
    }

    /// A run from given weights (plain device), optimiser and step counter, the parameters of
    /// `train.frozen` frozen ([`freeze`]); with `train.ema_decay`, the average starts at these
    /// weights.
    pub fn with_model(
        parts: TrainParts,
        model: RaftStereo,
        device: &Device,
        optimizer: ModuleOptimizer,
        step: usize,
    ) -> Result<Self> {
        parts.validate()?;
        parts.check_named_weights_resolved()?;
        let autodiff = device.clone().autodiff();
        let model = freeze(model.fork(&autodiff).train(), &parts.train.frozen)?;
        let schedule =
            OneCycleLr::new(parts.train.lr, parts.train.schedule_total_steps(), parts.train.warmup_fraction)?;
        let data = TrainingData::new(&parts.data, &parts.train)?;
        let prior = parts.prior.init(device)?;
        let ema = parts.train.ema_decay.map(|decay| Ema::new(decay, model.valid()));
        Ok(Self {
            parts,
            model,
            optimizer,
            schedule,
            step,
            ema,
            device: device.clone(),
            autodiff,
            notices: Vec::new(),
            last_step_seconds: StepSeconds::default(),
            last_exchange_bytes: 0,
            data,
            prior,
        })
    }

    /// Takes one step on the run's batch of the current step ([`crate::batch`]): the
    /// data-parallel step in a world of one ([`Trainer::step_among`] with [`SingleProcess`]).
    /// On NaN or inf in the loss or the gradients, fails naming the step and what was not
    /// finite, and leaves the weights and optimiser state untouched.
    pub fn step(&mut self) -> Result<StepReport> {
        self.step_among(&SingleProcess, None)
    }

    /// Takes one step on `batch` (on the autodiff device): prior, forward over all training
    /// iterations, loss, backward, clipping, AdamW at the schedule's rate of the current step;
    /// [`Trainer::step_on_among`] in a world of one. `observe`, when given, sees the predictions
    /// and the gradients before clipping ([`StepInternals`]); conformance checks read them
    /// there. Fails as [`Trainer::step`].
    pub fn step_on(
        &mut self,
        batch: &TensorBatch,
        observe: Option<&mut dyn FnMut(StepInternals<'_>)>,
    ) -> Result<StepReport> {
        self.step_on_among(batch, &SingleProcess, observe)
    }

    /// The batch's prior and the network's training pass: the disparity after every training
    /// iteration and, from a network that upsamples its start, the initial disparity.
    pub(crate) fn predictions(&self, batch: &TensorBatch) -> Result<TrainingDisparities> {
        let prior = batch_prior(&self.prior, self.parts.model.needs_prior(), batch)?;
        dgstereo_model::padded_training_disparities(
            &self.model,
            &self.parts.model,
            batch.left.clone(),
            batch.right.clone(),
            prior.as_ref(),
            self.parts.train.iters,
        )
    }

    /// The end of every step: clipping by global norm, AdamW at the schedule's rate, the moving
    /// average, the step counter and the report. `seconds` holds the parts already taken; the
    /// optimiser's share is measured here. Fails, touching nothing, on a non-finite gradient.
    pub(crate) fn apply_gradients(
        &mut self,
        grads: GradientsParams,
        loss_value: f64,
        sums: &MetricSums,
        seconds: StepSeconds,
    ) -> Result<StepReport> {
        let step = self.step;
        let started = Instant::now();
        let (grads, clip) = clip_global_norm(&self.model, grads, self.parts.train.clip);
        if let Some(param) = clip.non_finite {
            let what = format!("the gradient of '{param}' (loss {loss_value})");
            return Err(Error::not_finite(what).context(stopping_at(step)));
        }
        let lr = self.schedule.lr(step);
        self.model = self.optimizer.step(lr, self.model.clone(), grads);
        self.step += 1;
        if let Some(ema) = &mut self.ema {
            ema.update(&self.model, self.step);
        }
        self.last_step_seconds = StepSeconds { optimizer: started.elapsed().as_secs_f64(), ..seconds };
        let m = sums.metrics();
        Ok(StepReport { step, loss: loss_value, epe: m.epe, bad3: m.bad_3, lr, grad_norm: clip.total_norm })
    }

    /// The prior provider of the run.
    pub fn prior(&self) -> &Prior {
        &self.prior
    }

    /// The run's parts.
    pub fn parts(&self) -> &TrainParts {
        &self.parts
    }

    /// Steps completed so far (the index of the next step).
    pub fn completed_steps(&self) -> usize {
        self.step
    }

    /// The plain device (validation, data).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The autodiff device the network trains on (where a caller builds its batches for
    /// [`Trainer::step_on`]).
    pub fn autodiff_device(&self) -> &Device {
        &self.autodiff
    }

    /// What the user should know about how the trainer was set up (weights that kept their
    /// initialisation, a moving average that restarts): the caller shows them, a library never
    /// prints.
    pub fn notices(&self) -> &[String] {
        &self.notices
    }

    /// The decay of the weights' moving average, when the run keeps one (`train.ema_decay`; a
    /// run resumed without it keeps none).
    pub fn moving_average_decay(&self) -> Option<f64> {
        self.ema.as_ref().map(Ema::decay)
    }

    /// What the parts of the last step took.
    pub fn last_step_seconds(&self) -> StepSeconds {
        self.last_step_seconds
    }

    /// Bytes each rank contributed to the last step's gradient exchange (0 in one process).
    pub fn last_exchange_bytes(&self) -> usize {
        self.last_exchange_bytes
    }

    /// The trained weights without autodiff (not averaged; see [`Trainer::shipped_model`]).
    pub fn inference_model(&self) -> RaftStereo {
        self.model.valid()
    }

    /// The weights the run validates, stores under the model keys of its checkpoints and
    /// writes as its final model: the moving average when `train.ema_decay` is set, else the
    /// trained weights.
    pub fn shipped_model(&self) -> RaftStereo {
        match &self.ema {
            Some(ema) => ema.model().clone(),
            None => self.inference_model(),
        }
    }
}
impl Trainer {
    /// Each stage's forward and backward seconds on `batch`, run alone with the step's prior and
    /// iterations ([`dgstereo_model::stage_backward::profile_backward`]; `dgstereo bench --train --stages`).
    pub fn stage_backward_seconds(
        &self,
        batch: &TensorBatch,
    ) -> dgstereo_core::Result<Vec<dgstereo_model::stage_backward::StageBackward>> {
        let prior = batch_prior(self.prior(), self.parts.model.needs_prior(), batch)?;
        let [_, _, h, w] = batch.left.dims();
        let padder = dgstereo_core::InputPadder::new(h, w, self.parts.model.pad_divisor());
        let prior = prior.map(|p| dgstereo_core::DepthPrior { left: padder.pad(p.left), right: padder.pad(p.right) });
        let (left, right) = (padder.pad(batch.left.clone()), padder.pad(batch.right.clone()));
        dgstereo_model::stage_backward::profile_backward(
            &self.model,
            left,
            right,
            prior.as_ref(),
            self.parts.train.iters,
        )
    }
}
