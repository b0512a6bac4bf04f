//! [`PriorConfig`] (the `[prior]` table) and the provider it builds, [`Prior`].

use std::path::PathBuf;

use burn::tensor::Device;
use dgstereo_core::{Error, Problem, Result};
use serde::{Deserialize, Serialize};

use crate::depth_anything::dinov2::PATCH_SIZE;
use crate::depth_anything::preprocess::DEFAULT_INPUT_SIZE;
use crate::file::{DEFAULT_LEFT_PATTERN, DEFAULT_RIGHT_PATTERN};
use crate::{
    CachedPrior, DepthAnythingV2Encoder, DepthAnythingV2Prior, DepthPrior, FilePrior, PriorInput, PriorProvider,
    SimulatedPrior, SimulatedPriorConfig,
};

fn default_input_size() -> usize {
    DEFAULT_INPUT_SIZE
}
fn default_left_pattern() -> String {
    DEFAULT_LEFT_PATTERN.to_string()
}
fn default_right_pattern() -> String {
    DEFAULT_RIGHT_PATTERN.to_string()
}

/// Which prior provider an experiment uses (TOML: a `[prior]` table with `kind = "..."`).
///
/// ```toml
/// [prior]
/// kind = "depth-anything-v2"          # or "none" (the default), "file", "cache", "simulated"
/// weights = "weights/depth_anything_v2_vits.pth"
/// encoder = "vits"                    # optional: read from the checkpoint, checked when given
/// input_size = 518                    # optional
///
/// # [prior] kind = "file", dir = "priors", left = "{name}_left", right = "{name}_right"
/// # [prior] kind = "simulated", seed = 0, scale = [0.5, 2.0], shift = [0.0, 0.3],
/// #         gamma = [0.7, 1.4], blur_sigma = 1.5, noise_std = 0.01
/// # [prior] kind = "cache", dir = "cache/priors"  with the wrapped provider in [prior.inner]
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum PriorConfig {
    /// No prior: plain RAFT-Stereo.
    None {},
    /// Depth Anything V2 run on both views ([`DepthAnythingV2Prior`]).
    DepthAnythingV2 {
        /// The official checkpoint (`depth_anything_v2_vit{s,b,l}.pth`). Required.
        weights: PathBuf,
        /// Encoder size; read from the checkpoint when omitted, checked against it when given.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        encoder: Option<DepthAnythingV2Encoder>,
        /// Lower bound of the network input's shorter side (official `--input-size`, 518).
        #[serde(default = "default_input_size")]
        input_size: usize,
    },
    /// Precomputed priors read from files named after the pairs ([`FilePrior`]).
    File {
        /// The folder holding the files.
        dir: PathBuf,
        /// File-name pattern of left priors relative to `dir`; `{name}` is the pair's name, and
        /// `.npy`, `.pfm`, `.png` are tried when it has no extension.
        #[serde(default = "default_left_pattern")]
        left: String,
        /// File-name pattern of right priors.
        #[serde(default = "default_right_pattern")]
        right: String,
    },
    /// Another provider whose outputs are stored on disk by content hash ([`CachedPrior`]).
    Cache {
        /// The cache folder (created when missing).
        dir: PathBuf,
        /// The wrapped provider.
        inner: Box<PriorConfig>,
    },
    /// A prior simulated from ground-truth disparity ([`SimulatedPrior`]).
    Simulated(SimulatedPriorConfig),
}

impl Default for PriorConfig {
    fn default() -> Self {
        Self::None {}
    }
}

/// A built provider, chosen by [`PriorConfig`].
#[derive(Debug, Clone)]
pub enum Prior {
    /// No prior.
    None,
    /// Depth Anything V2.
    DepthAnythingV2(Box<DepthAnythingV2Prior>),
    /// Files.
    File(FilePrior),
    /// A cached provider.
    Cache(CachedPrior<Box<Prior>>),
    /// Simulated from ground truth.
    Simulated(SimulatedPrior),
}

impl PriorConfig {
    /// Builds the provider. Fails, naming the key, when a checkpoint or folder is missing or a
    /// value is out of range; there is no fallback to another provider.
    pub fn init(&self, device: &Device) -> Result<Prior> {
        match self {
            Self::None {} => Ok(Prior::None),
            Self::DepthAnythingV2 { weights, encoder, input_size } => Ok(Prior::DepthAnythingV2(Box::new(
                DepthAnythingV2Prior::load(weights, *encoder, *input_size, device)?,
            ))),
            Self::File { dir, left, right } => {
                if !dir.is_dir() {
                    return Err(Error::config("prior.dir", format!("'{}': no such folder", dir.display())));
                }
                Ok(Prior::File(FilePrior::new(dir.clone(), left.clone(), right.clone())))
            }
            Self::Cache { dir, inner } => {
                let provider = inner.init(device)?;
                Ok(Prior::Cache(CachedPrior::new(
                    Box::new(provider),
                    inner.fingerprint()?,
                    dir.clone(),
                    inner.uses_ground_truth(),
                )?))
            }
            Self::Simulated(config) => Ok(Prior::Simulated(SimulatedPrior::new(config.clone())?)),
        }
    }

    /// One configuration of every kind, in the order of the enum (paths empty); tests draw the
    /// kinds from here (`every_kind_is_listed` fails when a kind is missing).
    pub fn variants() -> Vec<Self> {
        vec![
            Self::None {},
            Self::DepthAnythingV2 { weights: PathBuf::new(), encoder: None, input_size: DEFAULT_INPUT_SIZE },
            Self::File { dir: PathBuf::new(), left: default_left_pattern(), right: default_right_pattern() },
            Self::Cache { dir: PathBuf::new(), inner: Box::new(Self::Simulated(SimulatedPriorConfig::default())) },
            Self::Simulated(SimulatedPriorConfig::default()),
        ]
    }

    /// The kind's name as the TOML key `kind` writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::None {} => "none",
            Self::DepthAnythingV2 { .. } => "depth-anything-v2",
            Self::File { .. } => "file",
            Self::Cache { .. } => "cache",
            Self::Simulated(_) => "simulated",
        }
    }

    /// Everything wrong with the configuration without reading files, keys relative to the
    /// prior table (`weights`, `inner.kind`): empty paths, an input size below the ViT patch,
    /// a cache around a provider that gives no prior, the simulated ranges. Whether the files
    /// exist is checked by [`init`](Self::init).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        let mut add = |key: &str, reason: &str| problems.push(Problem::new(key, reason));
        match self {
            Self::None {} => {}
            Self::DepthAnythingV2 { weights, input_size, .. } => {
                if weights.as_os_str().is_empty() {
                    add("weights", "is empty: name the Depth Anything V2 checkpoint");
                }
                if *input_size < PATCH_SIZE {
                    add("input_size", &format!("{input_size} is below the ViT patch size {PATCH_SIZE}"));
                }
            }
            Self::File { dir, .. } => {
                if dir.as_os_str().is_empty() {
                    add("dir", "is empty: name the folder of the prior files");
                }
            }
            Self::Cache { dir, inner } => {
                if dir.as_os_str().is_empty() {
                    add("dir", "is empty: name the cache folder");
                }
                if !inner.gives_prior() {
                    add("inner.kind", "a cache must wrap a provider that gives a prior");
                }
                problems.extend(inner.problems().into_iter().map(|p| p.within("inner")));
            }
            Self::Simulated(simulated) => problems.extend(simulated.problems()),
        }
        problems
    }

    /// Checks the configuration without reading files.
    ///
    /// # Errors
    /// [`Error::Config`] with the first of [`problems`](Self::problems).
    pub fn validate(&self) -> Result<()> {
        Problem::first(self.problems())
    }

    /// Whether this configuration yields a prior.
    pub fn gives_prior(&self) -> bool {
        match self {
            Self::None {} => false,
            Self::Cache { inner, .. } => inner.gives_prior(),
            _ => true,
        }
    }

    /// Whether the provider reads the ground truth (then it is needed at inference too).
    pub fn uses_ground_truth(&self) -> bool {
        match self {
            Self::Simulated(_) => true,
            Self::Cache { inner, .. } => inner.uses_ground_truth(),
            _ => false,
        }
    }

    /// A string that changes whenever the provider's output may: the configuration as JSON, plus
    /// the size and modification time of a checkpoint.
    pub fn fingerprint(&self) -> Result<String> {
        let mut fingerprint = serde_json::to_string(self).map_err(|e| Error::encode("the prior configuration", e))?;
        if let Self::DepthAnythingV2 { weights, .. } = self {
            let meta = std::fs::metadata(weights).map_err(|e| Error::io(weights, e))?;
            let modified = meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
            fingerprint += &format!(";weights_len={};modified={:?}", meta.len(), modified.map(|d| d.as_secs()));
        }
        Ok(fingerprint)
    }
}

impl PriorProvider for Prior {
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>> {
        match self {
            Self::None => Ok(None),
            Self::DepthAnythingV2(p) => p.provide(input),
            Self::File(p) => p.provide(input),
            Self::Cache(p) => p.provide(input),
            Self::Simulated(p) => p.provide(input),
        }
    }
}
