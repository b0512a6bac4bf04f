//! Runs the trainer's two steps on the reference's batch and compares.

use std::collections::BTreeMap;
use std::path::Path;

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, Result};
use dgstereo_loss::LossConfig;
use dgstereo_model::RaftStereo;
use dgstereo_model::checkpoint::load_pytorch;
use dgstereo_model::encoder::EncoderLayout;
use dgstereo_model::official_keys::Family;
use dgstereo_model::official_keys::renames::alias_of_ignored;
use serde::Deserialize;

use super::alteration::{Alteration, optimizer};
use super::reference::{GRADIENT_PREFIX, PARAMETER_PREFIX, ReferenceTensor, TrainStepReference};
use super::report::{
    CheckKind, CheckLine, GRAD_NORM_TOLERANCE, LOSS_TOLERANCE, LR_TOLERANCE, TrainStepReport, gradient_check, missing,
    prediction_check, recipe_check, scalar_check, update_check,
};
use crate::trainer::{StepInternals, TrainParts, Trainer, init_model};

/// The parts of `train_stereo.py`'s recipe that the reference file's metadata does not carry:
/// PyTorch's AdamW betas and the script's `OneCycleLR` arguments.
const REFERENCE_BETAS: [f64; 2] = [0.9, 0.999];
const REFERENCE_PCT_START: f64 = 0.01;
const REFERENCE_EXTRA_STEPS: usize = 100;

/// Runs `recipe` (an experiment's parts, e.g. the defaults) for the reference's two steps, with
/// the official checkpoint `weights` as the starting point, and compares with `reference`.
///
/// The run takes from the reference what is particular to it: the batch (its size and crop),
/// `iters`, `num_steps` (the schedule's `train.steps`) and `lr`. Everything else is the recipe's:
/// the recipe lines of the report compare those values with the reference's. `alteration`
/// deliberately breaks one component after those lines, to show that the checks catch it.
///
/// # Errors
/// The reference file is unreadable or lacks a key; the checkpoint does not load into the
/// recipe's model; the recipe does not validate; a step fails.
pub fn verify_train_step(
    weights: &Path,
    reference: &Path,
    recipe: &TrainParts,
    alteration: Option<Alteration>,
    device: &Device,
) -> Result<TrainStepReport> {
    let reference = TrainStepReference::read(reference)?;
    let mut lines = recipe_lines(recipe, &reference)?;
    let mut parts = recipe.clone();
    let left = reference.tensor("input.left")?;
    let [batch_size, height, width] = match left.shape.as_slice() {
        &[n, _, h, w] => [n, h, w],
        other => {
            return Err(Error::format(&reference.path, format!("input.left: expected 4 dimensions, found {other:?}")));
        }
    };
    parts.train.iters = reference.meta("iters")?;
    parts.train.steps = reference.meta("num_steps")?;
    parts.train.lr = reference.meta("lr")?;
    parts.train.batch_size = batch_size;
    parts.train.crop = [height, width];
    if let Some(a) = alteration {
        a.apply(&mut parts);
    }

    let grad_names = reference.names_under(GRADIENT_PREFIX);
    let param_names = reference.names_under(PARAMETER_PREFIX);
    let model = load_pytorch(init_model(&parts.model, device, None)?, weights)?;
    let initial = named_values(&model, &param_names, None);
    let optimizer = optimizer(&parts.train, alteration);
    let mut trainer = Trainer::with_model(parts, model, device, optimizer, 0)?;
    let batch = reference.batch(&trainer.autodiff)?;

    let mut predictions = Vec::new();
    let mut gradients = BTreeMap::new();
    let mut observe = |step: StepInternals<'_>| {
        predictions = step.predictions.iter().map(|p| to_vec(p.clone().detach())).collect();
        gradients = named_values(step.model, &grad_names, Some(step.grads));
    };
    let first = trainer.step_on(&batch, Some(&mut observe))?;
    let second = trainer.step_on(&batch, None)?;
    let updated = named_values(&trainer.model, &param_names, None);

    for k in 0..reference.prediction_count() {
        let key = format!("step1.flow_up.{k}");
        let expected = reference.tensor(&key)?;
        match predictions.get(k) {
            // Our predictions are positive disparity, the reference's RAFT-Stereo's flow.
            Some(ours) => {
                let flow: Vec<f32> = ours.iter().map(|d| -d).collect();
                lines.push(prediction_check(&key, &expected.shape, &flow, &expected.values));
            }
            None => lines.push(missing(CheckKind::Prediction, &key, "no such iteration in our run")),
        }
    }
    let mut loss_error = 0.0f64;
    for (i, (step, tolerance)) in [first, second].iter().zip(LOSS_TOLERANCE).enumerate() {
        let (line, e) = scalar_check(
            CheckKind::Loss,
            &format!("step{}.loss", i + 1),
            step.loss,
            reference.scalar(&format!("step{}.loss", i + 1))?,
            tolerance,
        );
        loss_error = loss_error.max(e);
        lines.push(line);
    }
    for (i, step) in [first, second].iter().enumerate() {
        let key = format!("step{}.grad_norm", i + 1);
        lines.push(
            scalar_check(CheckKind::GradNorm, &key, step.grad_norm, reference.scalar(&key)?, GRAD_NORM_TOLERANCE).0,
        );
    }
    for (i, step) in [first, second].iter().enumerate() {
        let key = format!("step{}.lr", i + 1);
        lines.push(scalar_check(CheckKind::LearningRate, &key, step.lr, reference.scalar(&key)?, LR_TOLERANCE).0);
    }

    let global_norm = reference.scalar("step1.grad_norm")?;
    let (mut gradient_error, mut worst_gradient) = (0.0f64, String::from("none"));
    for name in &grad_names {
        let key = format!("{GRADIENT_PREFIX}{name}");
        let expected = reference.tensor(&key)?;
        match gradients.get(name) {
            Some(ours) if ours.shape == expected.shape => {
                let (line, relative) =
                    gradient_check(&key, &expected.shape, &ours.values, &expected.values, global_norm);
                if let Some(e) = relative.filter(|&e| e.is_nan() || e > gradient_error) {
                    (gradient_error, worst_gradient) = (e, name.clone());
                }
                lines.push(line);
            }
            Some(ours) => {
                lines.push(missing(CheckKind::Gradient, &key, &format!("our gradient has shape {:?}", ours.shape)))
            }
            None => lines.push(missing(CheckKind::Gradient, &key, "no such parameter, or no gradient, in our run")),
        }
    }

    let lr_sum = first.lr + second.lr;
    let mut update_agreement = 100.0f64;
    for name in &param_names {
        let key = format!("{PARAMETER_PREFIX}{name}");
        let expected = reference.tensor(&key)?;
        match (initial.get(name), updated.get(name)) {
            (Some(p0), Some(p2)) if p2.shape == expected.shape => {
                let (line, share) =
                    update_check(&key, &expected.shape, &p0.values, &p2.values, &expected.values, lr_sum);
                update_agreement = update_agreement.min(share);
                lines.push(line);
            }
            _ => lines.push(missing(CheckKind::Update, &key, "no such parameter of this shape in our model")),
        }
    }
    Ok(TrainStepReport { lines, loss_error, gradient_error, worst_gradient, update_agreement })
}

/// The reference's model arguments (the `config` metadata entry, `train_stereo.py`'s args).
#[derive(Debug, Deserialize)]
struct OfficialArgs {
    hidden_dims: Vec<usize>,
    corr_implementation: String,
    shared_backbone: bool,
    corr_levels: usize,
    corr_radius: usize,
    n_downsample: usize,
    context_norm: String,
    slow_fast_gru: bool,
    n_gru_layers: usize,
    #[serde(default)]
    mixed_precision: bool,
}

/// The recipe's values against the reference's: optimiser, clip, schedule, loss and model.
fn recipe_lines(recipe: &TrainParts, reference: &TrainStepReference) -> Result<Vec<CheckLine>> {
    let t = &recipe.train;
    let mut lines = Vec::new();
    let mut number = |key: &str, ours: f64, theirs: f64| {
        lines.push(recipe_check(key, short(ours), short(theirs), relative_eq(ours, theirs)));
    };
    number("train.weight_decay", t.weight_decay, reference.meta("weight_decay")?);
    number("train.eps", t.eps, reference.meta("eps")?);
    number("train.clip", t.clip, reference.meta("clip")?);
    number("train.betas[0]", t.betas[0], REFERENCE_BETAS[0]);
    number("train.betas[1]", t.betas[1], REFERENCE_BETAS[1]);
    number("train.warmup_fraction", t.warmup_fraction, REFERENCE_PCT_START);
    number("train.schedule_extra_steps", t.schedule_extra_steps as f64, REFERENCE_EXTRA_STEPS as f64);
    let gamma: f64 = reference.meta("loss_gamma")?;
    let max_flow: f64 = reference.meta("max_flow")?;
    match recipe.loss {
        LossConfig::SequenceL1 { gamma: g, max_disparity, .. } => {
            number("loss.gamma", g, gamma);
            number("loss.max_disparity", max_disparity, max_flow);
        }
        ref other => {
            let kind = if matches!(other, LossConfig::EdgeAware { .. }) { "edge-aware" } else { "another loss" };
            lines.push(recipe_check("loss.kind", kind, "sequence-l1", false));
        }
    }
    let config: String = reference.meta("config")?;
    let args: OfficialArgs = serde_json::from_str(&config).map_err(|e| {
        Error::format(&reference.path, format!("metadata entry 'config' is not the model's arguments: {e}"))
    })?;
    let m = &recipe.model;
    let mut same = |key: &str, ours: String, theirs: String| {
        let passed = ours == theirs;
        lines.push(recipe_check(key, ours, theirs, passed));
    };
    same("model.updater.hidden_dims", format!("{:?}", m.updater.hidden_dims), format!("{:?}", args.hidden_dims));
    same("model.updater.n_gru_layers", m.updater.n_gru_layers.to_string(), args.n_gru_layers.to_string());
    same("model.updater.n_downsample", m.updater.n_downsample.to_string(), args.n_downsample.to_string());
    same("model.updater.slow_fast_gru", m.updater.slow_fast_gru.to_string(), args.slow_fast_gru.to_string());
    same("model.correlation.implementation", serde_name(&m.correlation.implementation), args.corr_implementation);
    same("model.correlation.levels", m.correlation.levels.to_string(), args.corr_levels.to_string());
    same("model.correlation.radius", m.correlation.radius.to_string(), args.corr_radius.to_string());
    same("model.encoder.context_norm", serde_name(&m.encoder.context_norm), args.context_norm);
    let layout = if args.shared_backbone { EncoderLayout::SharedBackbone } else { EncoderLayout::Separate };
    same("model.encoder.layout", m.encoder.layout.name().into(), layout.name().into());
    same("model.precision", "float32".into(), if args.mixed_precision { "mixed" } else { "float32" }.into());
    same("model (depth prior)", if m.needs_prior() { "used" } else { "none" }.into(), "none".into());
    Ok(lines)
}

/// The serde name of a configuration enum (`"reg"`, `"batch"`), as the reference spells it.
fn serde_name<T: serde::Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(other) => other.to_string(),
        Err(e) => format!("<{e}>"),
    }
}

/// `v` as written in a configuration: plain between 0.001 and 10^6, else in exponent form.
fn short(v: f64) -> String {
    if v == 0.0 || (1e-3..1e6).contains(&v.abs()) { v.to_string() } else { format!("{v:e}") }
}

fn relative_eq(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

/// Collects, by official name, the values of the parameters of `model` named in `names` (with
/// `grads`: their gradients). Paths are built as burn-store builds them for checkpoints: enum
/// variants are not part of a path.
fn named_values(
    model: &RaftStereo,
    names: &[String],
    grads: Option<&GradientsParams>,
) -> BTreeMap<String, ReferenceTensor> {
    let path = |n: &str| alias_of_ignored(&Family::RaftStereo.module_path_of_official_key(n));
    let wanted: BTreeMap<String, String> = names.iter().map(|n| (path(n), n.clone())).collect();
    let mut collector = Collector { wanted, grads, path: Vec::new(), found: BTreeMap::new() };
    model.visit(&mut collector);
    collector.found
}

struct Collector<'a> {
    wanted: BTreeMap<String, String>,
    grads: Option<&'a GradientsParams>,
    path: Vec<Option<String>>,
    found: BTreeMap<String, ReferenceTensor>,
}

impl ModuleVisitor for Collector<'_> {
    fn enter_module(&mut self, name: &str, container_type: &str) {
        self.path.push((!container_type.starts_with("Enum:")).then(|| name.to_string()));
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let path: Vec<&str> = self.path.iter().flatten().map(String::as_str).collect();
        let Some(official) = self.wanted.get(&path.join(".")) else { return };
        let tensor = match self.grads {
            Some(grads) => match grads.get::<D>(param.id) {
                Some(g) => g,
                None => return,
            },
            None => param.val(),
        };
        let shape = tensor.dims().to_vec();
        self.found.insert(official.clone(), ReferenceTensor { shape, values: to_vec(tensor.detach()) });
    }
}
