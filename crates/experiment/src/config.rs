//! [`ExperimentConfig`]: everything a run needs, and the checks of its values and combinations.
//!
//! Each section validates in its own crate and lists its [`Problem`]s keyed relative to its
//! table (`tau`, `updater.guidance`); this module gathers them under the section's name
//! (`loss.tau`) and adds the checks that span sections: the run name, whether the model's need
//! for a depth prior ([`ModelConfig::check_prior`]) and the prior provider agree, and the crop
//! against the network's output grid.

use dgstereo_core::{Error, Problem};
use dgstereo_eval::BenchmarkConfig;
use dgstereo_loss::LossConfig;
use dgstereo_model::ModelConfig;
use dgstereo_prior::PriorConfig;
use serde::{Deserialize, Serialize};

use crate::training::{TrainingConfig, TrainingDataConfig};

/// The complete configuration of one run.
///
/// Every section has a default (RAFT-Stereo without a prior, trained with its sequence loss), so
/// a file writes only what differs; the resolved configuration written next to outputs and
/// checkpoints ([`to_toml`](Self::to_toml)) holds every key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// The run's name (the file's `name`, or its stem, plus the sweep suffix).
    pub name: String,
    /// What the run is for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The network (`[model]`).
    #[serde(default)]
    pub model: ModelConfig,
    /// The depth prior provider (`[prior]`).
    #[serde(default)]
    pub prior: PriorConfig,
    /// The training loss (`[loss]`).
    #[serde(default)]
    pub loss: LossConfig,
    /// The optimisation recipe (`[train]`).
    #[serde(default)]
    pub train: TrainingConfig,
    /// The training data (`[data]`).
    #[serde(default)]
    pub data: TrainingDataConfig,
    /// The benchmarks `dgstereo ablate` scores each run on (`[[benchmarks]]`), beside the run's
    /// held-out synthetic set. Their folders need to exist only when a run is evaluated.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub benchmarks: Vec<BenchmarkConfig>,
    /// Scheduler options (`[launcher]`), for `dgstereo ablate --launcher slurm`.
    #[serde(default, skip_serializing_if = "crate::launcher::LauncherConfig::is_default")]
    pub launcher: crate::launcher::LauncherConfig,
}

impl ExperimentConfig {
    /// Every section's default (RAFT-Stereo without a prior, its sequence loss and recipe, the
    /// synthetic data) under the run name `name`: what an experiment file with only a name gives.
    pub fn named(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            description: None,
            model: ModelConfig::default(),
            prior: PriorConfig::default(),
            loss: LossConfig::default(),
            train: TrainingConfig::default(),
            data: TrainingDataConfig::default(),
            benchmarks: Vec::new(),
            launcher: crate::launcher::LauncherConfig::default(),
        }
    }

    /// The configuration as a complete TOML file (every key, defaults included); loading it as an
    /// experiment file gives this configuration back.
    pub fn to_toml(&self) -> String {
        // The types serialise to TOML by construction (no maps with non-string keys, integers
        // read from TOML fit i64); should that ever change, the file says so instead of panicking.
        toml::to_string(self).unwrap_or_else(|e| format!("# this configuration could not be written as TOML: {e}\n"))
    }

    /// Checks values and combinations.
    ///
    /// # Errors
    /// [`Error::Config`] with the first of [`problems`](Self::problems).
    pub fn validate(&self) -> dgstereo_core::Result<()> {
        Problem::first(self.problems())
    }

    /// Everything wrong with the configuration, most basic first (empty when valid), keys as the
    /// experiment file writes them.
    pub fn problems(&self) -> Vec<Problem> {
        fn within(table: &str, found: Vec<Problem>) -> Vec<Problem> {
            found.into_iter().map(|p| p.within(table)).collect()
        }
        let mut problems = name_problems(&self.name);
        problems.extend(within("model", self.model.problems()));
        problems.extend(within("prior", self.prior.problems()));
        problems.extend(self.combination_problems());
        problems.extend(within("loss", self.loss.problems()));
        for (i, b) in self.benchmarks.iter().enumerate() {
            let table = format!("benchmarks[{i}]");
            problems.extend(within(&table, b.problems()));
            if self.benchmarks[..i].iter().any(|o| o.label() == b.label()) {
                let reason = format!("'{}' is used twice: give each benchmark a name", b.label());
                problems.push(Problem::new(format!("{table}.name"), reason));
            }
        }
        problems.extend(within("train", self.train.problems()));
        problems.extend(within("data", self.data.problems()));
        problems
    }

    /// A depth prior needs a consumer and fusion or guidance needs a prior; training crops fit
    /// the network's output grid; pretrained weights need the network they load into, and a loss
    /// on the initial disparity a network that gives one.
    fn combination_problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        // Unpadded, the network's full-resolution output is the crop rounded up to a multiple of
        // 2^n_downsample, which would not match the crop's ground truth.
        if (2..=3).contains(&self.model.updater.n_downsample) {
            let factor = self.model.factor();
            let crop = self.train.crop;
            if crop.iter().any(|side| side % factor != 0) {
                let reason =
                    format!("{crop:?}: both sides must be multiples of 2^model.updater.n_downsample = {factor}");
                problems.push(Problem::new("train.crop", reason));
            }
        }
        if self.train.monocular_init.is_some() && self.model.monocular.feature_channels().is_none() {
            let reason =
                "the model has no monocular network to load into: set model.monocular (kind = \"depth-anything-v2\")";
            problems.push(Problem::new("train.monocular_init", reason));
        }
        if self.train.feature_init.is_some() && !self.model.has_mobilenet_features() {
            let reason = "the model has no MobileNetV2 feature network to load into: set \
                          model.encoder.layout = \"mobilenet-pyramid\" (IGEV-Stereo)";
            problems.push(Problem::new("train.feature_init", reason));
        }
        if self.loss.needs_initial_disparity() && !self.model.outputs_initial_disparity() {
            let reason = "supervises the initial disparity the network upsamples itself, and this one has none: \
                          only model.initial_disparity kind = \"soft-argmin\" with model.updater.upsampling = \
                          \"superpixel\" (IGEV-Stereo) gives one";
            problems.push(Problem::new("loss.initial_disparity", reason));
        }
        let gives = self.prior.gives_prior();
        if let Err(Error::Config(problem)) = self.model.check_prior(gives) {
            problems.push(problem.within("model"));
        } else if gives && !self.model.needs_prior() {
            problems.push(Problem::new(
                "prior.kind",
                "a depth prior is configured but nothing uses it: set model.fusion.kind or model.updater.guidance, \
                 or set prior.kind = \"none\"",
            ));
        }
        problems
    }
}

/// Run names become folder names of outputs: printable, no whitespace, no `..`, relative.
fn name_problems(name: &str) -> Vec<Problem> {
    let bad_char = name
        .chars()
        .find(|c| c.is_whitespace() || c.is_control() || matches!(c, '\\' | ':' | '*' | '?' | '"' | '<' | '>' | '|'));
    let reason = if name.is_empty() {
        "the run name is empty".to_string()
    } else if let Some(c) = bad_char {
        format!("'{name}' contains {c:?}; run names become folder names")
    } else if name.starts_with('/') || name.split('/').any(|part| part.is_empty() || part == "." || part == "..") {
        format!("'{name}' must be a relative path without empty, '.' or '..' parts")
    } else {
        return Vec::new();
    };
    vec![Problem::new("name", reason)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_named_defaults_are_a_file_with_only_a_name() {
        let parsed: ExperimentConfig = toml::from_str("name = \"only\"").unwrap();
        assert_eq!(ExperimentConfig::named("only"), parsed);
    }
}
