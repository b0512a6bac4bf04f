//! An exponential moving average (EMA) of the trained weights (`train.ema_decay`, opt-in).
//!
//! A model trained on synthetic pairs can score very differently on real images from one
//! checkpoint to the next while its synthetic validation falls smoothly; averaging the weights
//! over the last few thousand steps makes the shipped model less of a draw. After each optimiser
//! step, every trainable float parameter is blended as `ema = d · ema + (1 − d) · w` with the
//! warmed-up decay `d = min(ema_decay, (1 + step) / (10 + step))` ([`warmed_decay`], `step`
//! counting the steps done), so the early average does not hold the initial weights for long.
//! Parameters that do not train (the frozen batch-norm statistics) are copied, not blended, so
//! they stay exact. The average is a plain [`RaftStereo`] on the run's plain device: no autodiff
//! graph, and validation and saving use it like any model.
//!
//! Design decision: when the EMA is on, a training checkpoint stores the *average* under the
//! model's own module paths and the raw trained weights under [`RAW_WEIGHTS_PREFIX`] (inside
//! `__train__.`, the prefix every weight reader already skips, like the optimiser state). So
//! everything that reads a checkpoint as weights (`dgstereo infer --weights`, `train.init`, the
//! ablation's scores) gets the averaged model without knowing about the EMA, while resuming
//! reads the raw weights back into the trained network and the average into the EMA, and
//! continues exactly. `model.safetensors` of a finished run is the average too.

use std::collections::{BTreeMap, BTreeSet};

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::Tensor;
use dgstereo_model::RaftStereo;

use crate::params::{PathStack, float_params};

/// The key prefix, in a checkpoint of a run with EMA, of the raw trained weights (followed by
/// the parameter's module path); the model's own keys then hold the average.
pub const RAW_WEIGHTS_PREFIX: &str = "__train__.raw.";

/// The decay used after `step` optimiser steps: `min(decay, (1 + step) / (10 + step))`.
pub fn warmed_decay(decay: f64, step: usize) -> f64 {
    let step = step as f64;
    decay.min((1.0 + step) / (10.0 + step))
}

/// The moving average of a run's weights.
#[derive(Debug, Clone)]
pub struct Ema {
    decay: f64,
    model: RaftStereo,
}

impl Ema {
    /// An average that starts at `weights` (a model on the plain device, e.g. `model.valid()`).
    pub fn new(decay: f64, weights: RaftStereo) -> Self {
        Self { decay, model: weights }
    }

    /// The configured `ema_decay`.
    pub fn decay(&self) -> f64 {
        self.decay
    }

    /// The averaged weights (plain device).
    pub fn model(&self) -> &RaftStereo {
        &self.model
    }

    /// Blends the weights of `trained` (the network on the autodiff device) into the average,
    /// `step` being the number of optimiser steps done (1 after the first).
    pub fn update(&mut self, trained: &RaftStereo, step: usize) {
        let trainable: BTreeSet<String> =
            float_params(trained).into_iter().filter(|(_, _, grad)| *grad).map(|(path, _, _)| path).collect();
        let mut collector = FlatWeights { path: PathStack::default(), found: BTreeMap::new() };
        trained.valid().visit(&mut collector);
        let mut blend = Blend {
            path: PathStack::default(),
            weights: collector.found,
            trainable: &trainable,
            decay: warmed_decay(self.decay, step),
        };
        self.model = self.model.clone().map(&mut blend);
    }
}

/// Collects every float parameter, flattened, by module path.
struct FlatWeights {
    path: PathStack,
    found: BTreeMap<String, Tensor<1>>,
}

impl ModuleVisitor for FlatWeights {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.enter(name);
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.exit();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let value = param.val();
        let n = value.shape().num_elements();
        self.found.insert(self.path.current(), value.reshape([n]));
    }
}

/// Blends the average's parameters with the weights of the same paths.
struct Blend<'a> {
    path: PathStack,
    weights: BTreeMap<String, Tensor<1>>,
    trainable: &'a BTreeSet<String>,
    decay: f64,
}

impl ModuleMapper for Blend<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.enter(name);
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.exit();
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let path = self.path.current();
        // Both modules come from one configuration, so every path is there.
        let Some(weight) = self.weights.remove(&path) else { return param };
        let (d, trainable) = (self.decay, self.trainable.contains(&path));
        param.map(|average| {
            let weight: Tensor<D> = weight.reshape(average.shape());
            if trainable { average.mul_scalar(d).add(weight.mul_scalar(1.0 - d)) } else { weight }
        })
    }
}
