//! The RAFT-Stereo configuration of an official checkpoint, read from its tensors.
//!
//! An official `.pth` holds no configuration, only a state dict, but the state dict shows most
//! of the architecture:
//! - **shared backbone**: a `conv2.*` head beside `cnet` and no `fnet.*`;
//! - **GRU levels** (`n_gru_layers`): how many `context_zqr_convs.{i}` there are (all three
//!   GRUs are built and stored whatever the level count; their input widths must agree);
//! - **n_downsample**: the mask head's output channels, `9·(2^n)²`;
//! - **hidden and context dims**: the GRUs' output channels;
//! - **context norm**: `cnet.norm1`'s tensors (running statistics: batch; affine parameters
//!   only: group; none: instance, the only parameterless norm an official checkpoint uses);
//! - **correlation levels × (2·radius + 1)**: the motion encoder's input channels, split as the
//!   official 4 levels and radius 4 where the product allows it, else radius 4, else 4 levels,
//!   else the fewest levels with an odd quotient;
//! - the trunk and feature widths.
//!
//! [`config_from_keys`] derives the configuration from those keys, builds the model and
//! compares its full key list with the file's, so a checkpoint that matches no consistent
//! configuration is an error listing the keys that disagree. What the tensors cannot show comes
//! from the official README's commands ([`OfficialPreset`]): the realtime architecture (shared
//! backbone, n_downsample 3, 2 GRU levels) runs with `slow_fast_gru` and 7 iterations, the
//! others with the defaults and 32 iterations. A DEFOM-Stereo checkpoint adds its own variants
//! ([`crate::defom_config`]) and runs with its evaluation's arguments.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use burn::tensor::Device;
use dgstereo_core::{Error, Problem, Result};
use dgstereo_encoder::{EncoderLayout, NormKind};

use crate::key_shapes::{dim, gru_levels};
use crate::official_keys::{KeyShape, ignored_by_loader, model_official_keys, pth_keys};
use crate::{ModelConfig, RaftStereo, checkpoint, defom_config, igev_config};

/// The most disagreeing keys an error lists.
const LISTED: usize = 12;

/// The official README command whose flags fill in what the tensors cannot show.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OfficialPreset {
    /// `raftstereo-realtime.pth`: `--shared_backbone --n_downsample 3 --n_gru_layers 2
    /// --slow_fast_gru --valid_iters 7` (and the CUDA sampler with mixed precision, which compute
    /// the same volume as `reg`).
    Realtime,
    /// `iraftstereo_rvc.pth`: `--context_norm instance`, 32 iterations.
    InstanceContext,
    /// `raftstereo-{sceneflow,middlebury,eth3d}.pth`: the argparse defaults, 32 iterations.
    Default,
    /// `defomstereo_*.pth`: `evaluate_stereo.py`'s defaults, 32 iterations of which 8 scale
    /// iterations ([`crate::defom_config`]).
    Defom,
    /// IGEV-Stereo's `sceneflow.pth` (and its fine-tuned checkpoints): `demo_imgs.py`'s
    /// defaults, `max_disp` 192, 32 iterations ([`crate::igev_config`]).
    Igev,
    /// An architecture no official checkpoint has: the argparse defaults for the rest.
    Custom,
}

impl OfficialPreset {
    /// The preset of a detected architecture.
    pub fn of(config: &ModelConfig) -> Self {
        if !matches!(config.monocular, dgstereo_prior::MonocularConfig::None {}) {
            return Self::Defom;
        }
        if config.correlation.geometry.is_some() {
            return Self::Igev;
        }
        let (e, u) = (&config.encoder, &config.updater);
        let c = &config.correlation;
        let standard = u.hidden_dims == [128; 3]
            && c.levels == 4
            && c.radius == 4
            && e.feature_dim == 256
            && e.trunk_dims == [64, 96, 128];
        if !standard {
            Self::Custom
        } else if e.layout == EncoderLayout::SharedBackbone
            && u.n_downsample == 3
            && u.n_gru_layers == 2
            && e.context_norm == NormKind::Batch
        {
            Self::Realtime
        } else if e.layout != EncoderLayout::Separate || u.n_downsample != 2 || u.n_gru_layers != 3 {
            Self::Custom
        } else if e.context_norm == NormKind::Instance {
            Self::InstanceContext
        } else if e.context_norm == NormKind::Batch {
            Self::Default
        } else {
            Self::Custom
        }
    }

    /// Whether the preset's command runs the slow-fast GRU schedule.
    pub fn slow_fast_gru(self) -> bool {
        self == Self::Realtime
    }

    /// The preset's `--valid_iters`.
    pub fn valid_iters(self) -> usize {
        match self {
            Self::Realtime => 7,
            _ => 32,
        }
    }

    /// A short name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Realtime => "realtime (raftstereo-realtime.pth)",
            Self::InstanceContext => "instance-norm context (iraftstereo_rvc.pth)",
            Self::Default => "default (raftstereo-sceneflow/middlebury/eth3d.pth)",
            Self::Defom => "DEFOM-Stereo (defomstereo_*.pth, evaluate_stereo.py's arguments)",
            Self::Igev => "IGEV-Stereo (sceneflow.pth, demo_imgs.py's arguments)",
            Self::Custom => "no official preset (argparse defaults)",
        }
    }
}

/// A configuration read from a checkpoint, with the preset that filled in the rest.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointConfig {
    /// The model configuration (architecture from the tensors, `slow_fast_gru` from the preset).
    pub model: ModelConfig,
    /// The preset.
    pub preset: OfficialPreset,
    /// Update iterations of the preset's command.
    pub valid_iters: usize,
}

impl fmt::Display for CheckpointConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, {} iterations; preset: {}", summary(&self.model), self.valid_iters, self.preset.name())
    }
}

/// The RAFT-Stereo options of `config` on one line (`shared backbone, n_downsample 3, 2 GRU
/// levels, ...`).
pub fn summary(config: &ModelConfig) -> String {
    let (e, u, c) = (&config.encoder, &config.updater, &config.correlation);
    let norm = serde_json::to_value(e.context_norm).ok().and_then(|v| v.as_str().map(String::from));
    let raft = format!(
        "{}, n_downsample {}, {} GRU levels, hidden {:?}, context_norm {}, corr {} levels x radius {}, slow_fast_gru {}",
        match e.layout {
            EncoderLayout::MobilenetPyramid => "MobileNetV2 feature pyramid",
            EncoderLayout::SharedBackbone => "shared backbone",
            EncoderLayout::Separate => "separate feature encoder",
        },
        u.n_downsample,
        u.n_gru_layers,
        u.hidden_dims,
        norm.unwrap_or_else(|| format!("{:?}", e.context_norm)),
        c.levels,
        c.radius,
        if u.slow_fast_gru { "on" } else { "off" },
    );
    match defom_config::summary(config).or_else(|| igev_config::summary(config)) {
        Some(variant) => format!("{raft}; {variant}"),
        None => raft,
    }
}

/// Splits the motion encoder's input channels into `(levels, radius)`: radius 4 and 4 levels
/// where the product allows it, else radius 4, else 4 levels, else the fewest levels whose
/// quotient is odd (at least 3); `None` when no split exists (a power of two).
pub fn correlation_split(channels: usize) -> Option<(usize, usize)> {
    if channels >= 9 && channels.is_multiple_of(9) {
        return Some((channels / 9, 4));
    }
    let odd = |levels: usize| channels.is_multiple_of(levels) && (channels / levels) % 2 == 1 && channels / levels >= 3;
    if odd(4) {
        return Some((4, (channels / 4 - 1) / 2));
    }
    (1..=channels).find(|&l| odd(l)).map(|l| (l, (channels / l - 1) / 2))
}

/// The architecture the primary keys show, or the problems with them.
fn architecture(keys: &BTreeMap<&str, &[usize]>) -> std::result::Result<ModelConfig, Vec<String>> {
    if igev_config::is_igev(keys) {
        return igev_config::architecture(keys, correlation_split);
    }
    let mut problems = Vec::new();
    let mut config = ModelConfig::default();
    let has = |prefix: &str| keys.keys().any(|k| k.starts_with(prefix));
    let shared = match (has("fnet."), has("conv2.")) {
        (false, true) => true,
        (true, false) => false,
        (true, true) => {
            problems.push(
                "both 'fnet.*' and 'conv2.*' keys: a model has a feature encoder or a shared backbone's head, not both"
                    .into(),
            );
            false
        }
        (false, false) => {
            problems.push("neither 'fnet.*' (feature encoder) nor 'conv2.*' (shared backbone's head)".into());
            false
        }
    };
    config.encoder.layout = if shared { EncoderLayout::SharedBackbone } else { EncoderLayout::Separate };
    config.encoder.feature_dim =
        dim(keys, if shared { "conv2.1.weight" } else { "fnet.conv2.weight" }, 0, &mut problems);
    config.encoder.trunk_dims = [
        dim(keys, "cnet.conv1.weight", 0, &mut problems),
        dim(keys, "cnet.layer2.0.conv1.weight", 0, &mut problems),
        dim(keys, "cnet.layer3.0.conv1.weight", 0, &mut problems),
    ];
    config.updater.hidden_dims = [
        dim(keys, "update_block.gru32.convz.weight", 0, &mut problems),
        dim(keys, "update_block.gru16.convz.weight", 0, &mut problems),
        dim(keys, "update_block.gru08.convz.weight", 0, &mut problems),
    ];
    config.updater.n_gru_layers = gru_levels(keys, &mut problems);
    let mask = dim(keys, "update_block.mask.2.weight", 0, &mut problems);
    match (2..=3).find(|n| 9 << (2 * n) == mask) {
        Some(n) => config.updater.n_downsample = n,
        None if mask > 0 => problems.push(format!(
            "'update_block.mask.2.weight' has {mask} output channels: not 9·(2^n)² for n_downsample 2 or 3"
        )),
        None => {}
    }
    let corr = dim(keys, "update_block.encoder.convc1.weight", 1, &mut problems);
    match correlation_split(corr) {
        Some((l, r)) => (config.correlation.levels, config.correlation.radius) = (l, r),
        None if corr > 0 => problems
            .push(format!("'update_block.encoder.convc1.weight' has {corr} input channels: not levels·(2·radius + 1)")),
        None => {}
    }
    config.encoder.context_norm = if keys.contains_key("cnet.norm1.running_mean") {
        NormKind::Batch
    } else if keys.contains_key("cnet.norm1.weight") {
        NormKind::Group
    } else {
        NormKind::Instance
    };
    let [d32, d16, d08] = config.updater.hidden_dims;
    if d32 != d08 {
        // `context_zqr_convs.0` takes the 1/4 context (`d08` channels) with `hidden_dims[0]` inputs,
        // in the reference as here.
        problems.push(format!(
            "'update_block.gru32.convz.weight' ({d32}) and 'update_block.gru08.convz.weight' ({d08}) \
             differ: the reference runs only with hidden_dims[0] = hidden_dims[2]"
        ));
    }
    if config.encoder.context_norm == NormKind::Group {
        let [c1, c2, c3] = config.encoder.trunk_dims;
        if let Some(w) = [c1, c2, c3, d32, d16, d08].into_iter().find(|w| *w < 8) {
            problems.push(format!("'cnet.norm1.weight' is a group norm (width/8 groups), but a width is {w}"));
        }
    }
    if defom_config::is_defom(keys) {
        defom_config::complete(&mut config, keys, &mut problems);
    }
    if problems.is_empty() { Ok(config) } else { Err(problems) }
}

/// How `file` (a checkpoint's keys) disagrees with `expected` (a model's): keys missing from the
/// file, keys the model lacks and shapes that differ, redundant keys ignored.
pub fn disagreements(expected: &[KeyShape], file: &[KeyShape]) -> Vec<String> {
    let file: BTreeMap<&str, &Vec<usize>> =
        file.iter().filter(|(k, _)| !ignored_by_loader(k)).map(|(k, s)| (k.as_str(), s)).collect();
    let model: BTreeMap<&str, &Vec<usize>> = expected.iter().map(|(k, s)| (k.as_str(), s)).collect();
    let mut out = Vec::new();
    for (k, s) in &model {
        match file.get(k) {
            None => out.push(format!("missing key '{k}' {s:?}")),
            Some(f) if f != s => out.push(format!("'{k}' has shape {f:?}, the configuration needs {s:?}")),
            Some(_) => {}
        }
    }
    out.extend(file.keys().filter(|k| !model.contains_key(*k)).map(|k| format!("unexpected key '{k}'")));
    out
}

fn listing(problems: &[String]) -> String {
    let more = problems.len().saturating_sub(LISTED);
    let mut s = problems.iter().take(LISTED).cloned().collect::<Vec<_>>().join("; ");
    if more > 0 {
        s.push_str(&format!("; and {more} more"));
    }
    s
}

/// The configuration whose official state dict `keys` is (keys without `module.`), built on
/// `device` to compare every key; the error lists the keys that disagree.
pub fn config_from_keys(keys: &[KeyShape], device: &Device) -> std::result::Result<CheckpointConfig, Problem> {
    config_and_model(keys, device).map(|(c, _)| c)
}

/// The configuration whose official state dict `keys` is, and a model of it built on `device`
/// (fresh weights, for the loader) after comparing its every key; the error lists the keys that
/// disagree.
pub fn model_from_keys(
    keys: &[KeyShape],
    device: &Device,
) -> std::result::Result<(CheckpointConfig, RaftStereo), Problem> {
    config_and_model(keys, device)
}

fn config_and_model(
    keys: &[KeyShape],
    device: &Device,
) -> std::result::Result<(CheckpointConfig, RaftStereo), Problem> {
    let primary: BTreeMap<&str, &[usize]> = keys.iter().map(|(k, s)| (k.as_str(), s.as_slice())).collect();
    // Keyed by the state dict as a whole: the listing names each key that disagrees.
    let fail = |p: &[String]| {
        let reason = format!(
            "the tensors match no consistent RAFT-Stereo (DEFOM-Stereo, IGEV-Stereo) configuration: {}",
            listing(p)
        );
        Problem::new("", reason)
    };
    let mut model_config = architecture(&primary).map_err(|p| fail(&p))?;
    model_config.validate().map_err(|e| fail(&[e.to_string()]))?;
    let preset = OfficialPreset::of(&model_config);
    model_config.updater.slow_fast_gru = preset.slow_fast_gru();
    let model = model_config.init(device).map_err(|e| fail(&[e.to_string()]))?;
    let problems = disagreements(&model_official_keys(&model), keys);
    if !problems.is_empty() {
        return Err(fail(&problems));
    }
    Ok((CheckpointConfig { model: model_config, preset, valid_iters: preset.valid_iters() }, model))
}

/// The configuration of an official `.pth` checkpoint ([`config_from_keys`] on its keys).
pub fn detect(path: &Path, device: &Device) -> Result<CheckpointConfig> {
    let keys = pth_keys(path)?;
    config_from_keys(&keys, device).map_err(|p| Error::Checkpoint { path: path.into(), message: p.to_string() })
}

/// Loads an official `.pth` checkpoint into the model of its detected configuration.
pub fn load_detected(path: &Path, device: &Device) -> Result<(RaftStereo, CheckpointConfig)> {
    let keys = pth_keys(path)?;
    let (config, model) =
        config_and_model(&keys, device).map_err(|p| Error::Checkpoint { path: path.into(), message: p.to_string() })?;
    Ok((checkpoint::load_pytorch(model, path)?, config))
}
