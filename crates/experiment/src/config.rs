//! [`ExperimentConfig`]: everything a run needs, and the checks of its values and combinations.

use std::fmt;

use dgstereo_eval::BenchmarkConfig;
use dgstereo_fusion::FusionConfig;
use dgstereo_loss::LossConfig;
use dgstereo_model::ModelConfig;
use dgstereo_prior::PriorConfig;
use dgstereo_train::{TrainingConfig, TrainingDataConfig};
use dgstereo_updater::GuidanceKind;
use serde::{Deserialize, Serialize};

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
}

/// One thing wrong with a configuration: the key at fault and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Dotted key, e.g. `model.updater.guidance`.
    pub key: String,
    /// What is wrong, and how to fix it where that is not obvious.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Messages of other crates' validators often start with the key already.
        if self.message.starts_with(&self.key) {
            write!(f, "{}", self.message)
        } else {
            write!(f, "{}: {}", self.key, self.message)
        }
    }
}

impl ExperimentConfig {
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
    /// [`dgstereo_core::Error::Config`] with every [`Problem`], `key: message`, joined by `; `.
    pub fn validate(&self) -> dgstereo_core::Result<()> {
        let problems = self.problems();
        if problems.is_empty() {
            return Ok(());
        }
        let text: Vec<String> = problems.iter().map(Problem::to_string).collect();
        Err(dgstereo_core::Error::Config(text.join("; ")))
    }

    /// Everything wrong with the configuration, most basic first (empty when valid).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        let mut add = |key: &str, message: String| problems.push(Problem { key: key.into(), message });
        check_name(&self.name, &mut add);
        check_model(&self.model, &mut add);
        check_prior(&self.prior, "prior", &mut add);
        check_combination(self, &mut add);
        check_loss(&self.loss, &mut add);
        check_benchmarks(&self.benchmarks, &mut add);
        for result in [self.train.validate(), self.data.validate()] {
            if let Err(e) = result {
                let message = match e {
                    dgstereo_core::Error::Config(m) => m,
                    other => other.to_string(),
                };
                add(&leading_key(&message), message.clone());
            }
        }
        problems
    }
}

/// The dotted key a validation message of another crate starts with (`train.lr = 0: ...`).
fn leading_key(message: &str) -> String {
    message
        .split(|c: char| c.is_whitespace() || c == ':' || c == '=')
        .next()
        .unwrap_or_default()
        .split('[')
        .next()
        .unwrap_or_default()
        .to_string()
}

/// Benchmark labels name table columns: each once; at least one iteration; a split, weather or
/// subset only on the data set it belongs to.
fn check_benchmarks(benchmarks: &[BenchmarkConfig], add: &mut impl FnMut(&str, String)) {
    for (i, b) in benchmarks.iter().enumerate() {
        if b.iters == 0 {
            add(&format!("benchmarks[{i}].iters"), "must be at least 1".into());
        }
        for (key, message) in b.option_problems() {
            add(&format!("benchmarks[{i}].{key}"), message);
        }
        if benchmarks[..i].iter().any(|o| o.label() == b.label()) {
            add(&format!("benchmarks[{i}].name"), format!("'{}' is used twice: give each benchmark a name", b.label()));
        }
    }
}

/// Run names become folder names of outputs: printable, no whitespace, no `..`, relative.
fn check_name(name: &str, add: &mut impl FnMut(&str, String)) {
    let bad_char = name
        .chars()
        .find(|c| c.is_whitespace() || c.is_control() || matches!(c, '\\' | ':' | '*' | '?' | '"' | '<' | '>' | '|'));
    if name.is_empty() {
        add("name", "the run name is empty".into());
    } else if let Some(c) = bad_char {
        add("name", format!("'{name}' contains {c:?}; run names become folder names"));
    } else if name.starts_with('/') || name.split('/').any(|part| part.is_empty() || part == "." || part == "..") {
        add("name", format!("'{name}' must be a relative path without empty, '.' or '..' parts"));
    }
}

fn check_model(model: &ModelConfig, add: &mut impl FnMut(&str, String)) {
    let mut found = Vec::new();
    let mut note = |key: &str, message: String| found.push((key.to_string(), message));
    let u = &model.updater;
    if !(1..=3).contains(&u.n_gru_layers) {
        note("model.updater.n_gru_layers", format!("{} is not 1, 2 or 3", u.n_gru_layers));
    }
    if !(2..=3).contains(&u.n_downsample) {
        note("model.updater.n_downsample", format!("{} is not 2 or 3", u.n_downsample));
    }
    if u.hidden_dims.contains(&0) {
        note("model.updater.hidden_dims", format!("{:?}: every width must be positive", u.hidden_dims));
    }
    if model.correlation.levels == 0 {
        note("model.correlation.levels", "must be at least 1".into());
    }
    if model.encoder.feature_dim == 0 {
        note("model.encoder.feature_dim", "must be positive".into());
    }
    if let FusionConfig::Deformable { features, .. } | FusionConfig::Conv { features, .. } = model.fusion
        && features < 3
    {
        note("model.fusion.features", format!("{features} is below 3"));
    }
    // Whatever the model crate checks beyond the above.
    if found.is_empty()
        && let Err(e) = model.validate()
    {
        found.push(("model".into(), e.to_string()));
    }
    for (key, message) in found {
        add(&key, message);
    }
}

fn check_prior(prior: &PriorConfig, key: &str, add: &mut impl FnMut(&str, String)) {
    match prior {
        PriorConfig::None => {}
        PriorConfig::DepthAnythingV2 { weights, input_size, .. } => {
            if weights.as_os_str().is_empty() {
                add(&format!("{key}.weights"), "is empty: name the Depth Anything V2 checkpoint".into());
            }
            if *input_size < 14 {
                add(&format!("{key}.input_size"), format!("{input_size} is below the ViT patch size 14"));
            }
        }
        PriorConfig::File { dir, .. } => {
            if dir.as_os_str().is_empty() {
                add(&format!("{key}.dir"), "is empty: name the folder of the prior files".into());
            }
        }
        PriorConfig::Cache { dir, inner } => {
            if dir.as_os_str().is_empty() {
                add(&format!("{key}.dir"), "is empty: name the cache folder".into());
            }
            if !inner.gives_prior() {
                add(&format!("{key}.inner.kind"), "a cache must wrap a provider that gives a prior".into());
            }
            check_prior(inner, &format!("{key}.inner"), add);
        }
        PriorConfig::Simulated(simulated) => {
            if let Err(e) = simulated.validate() {
                let message = match e {
                    dgstereo_core::Error::Config(m) => m,
                    other => other.to_string(),
                };
                // The prior crate names keys as `prior.KEY`; nested under a cache they move.
                let inner_key = leading_key(&message);
                let inner_key = inner_key.strip_prefix("prior").unwrap_or(&inner_key);
                add(&format!("{key}{inner_key}"), message);
            }
        }
    }
}

/// A depth prior needs a consumer, fusion or guidance needs a prior, and training crops fit the
/// network's output grid.
fn check_combination(config: &ExperimentConfig, add: &mut impl FnMut(&str, String)) {
    // Unpadded, the network's full-resolution output is the crop rounded up to a multiple of
    // 2^n_downsample, which would not match the crop's ground truth.
    if (2..=3).contains(&config.model.updater.n_downsample) {
        let factor = config.model.factor();
        let crop = config.train.crop;
        if crop.iter().any(|side| side % factor != 0) {
            add(
                "train.crop",
                format!("{crop:?}: both sides must be multiples of 2^model.updater.n_downsample = {factor}"),
            );
        }
    }
    let gives = config.prior.gives_prior();
    let fusion = &config.model.fusion;
    let guidance = config.model.updater.guidance;
    if !gives {
        if fusion.needs_prior() {
            add(
                "model.fusion.kind",
                format!("{} fusion needs a depth prior, but prior.kind is none: set [prior]", fusion_name(fusion)),
            );
        }
        if guidance != GuidanceKind::None {
            add(
                "model.updater.guidance",
                format!(
                    "{} guidance needs a depth prior, but prior.kind is none: set [prior]",
                    guidance_name(guidance)
                ),
            );
        }
    } else if !config.model.needs_prior() {
        add(
            "prior.kind",
            "a depth prior is configured but nothing uses it: set model.fusion.kind or \
             model.updater.guidance, or set prior.kind = \"none\""
                .into(),
        );
    }
}

fn check_loss(loss: &LossConfig, add: &mut impl FnMut(&str, String)) {
    let (gamma, max_disparity) = match *loss {
        LossConfig::SequenceL1 { gamma, max_disparity } => (gamma, max_disparity),
        LossConfig::EdgeAware { tau, gamma, max_disparity } => {
            if !(tau.is_finite() && tau >= 0.0) {
                add("loss.tau", format!("{tau} must be a finite value >= 0"));
            }
            (gamma, max_disparity)
        }
    };
    if !(gamma > 0.0 && gamma <= 1.0) {
        add("loss.gamma", format!("{gamma} must lie in (0, 1]"));
    }
    if !(max_disparity.is_finite() && max_disparity > 0.0) {
        add("loss.max_disparity", format!("{max_disparity} must be a finite value > 0"));
    }
}

fn fusion_name(fusion: &FusionConfig) -> &'static str {
    match fusion {
        FusionConfig::None => "none",
        FusionConfig::Deformable { .. } => "deformable",
        FusionConfig::Conv { .. } => "conv",
    }
}

fn guidance_name(guidance: GuidanceKind) -> &'static str {
    match guidance {
        GuidanceKind::None => "none",
        GuidanceKind::Gradient => "gradient",
        GuidanceKind::Depth => "depth",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leading_keys_of_other_crates_messages() {
        assert_eq!(leading_key("train.lr = 0: must be a finite value > 0"), "train.lr");
        assert_eq!(leading_key("data.sources[0].weight = -1: must be"), "data.sources");
        assert_eq!(leading_key("train.steps must be at least 1"), "train.steps");
    }
}
