//! [`TrainingConfig`] (the `[train]` table) and [`TrainingDataConfig`] (the `[data]` table).
//!
//! Every key has a default (RAFT-Stereo's recipe as used by the paper), so an empty table is the
//! reference run; unknown keys are errors naming the key.

use std::path::PathBuf;

use dgstereo_core::{Error, Result};
use dgstereo_data::SyntheticConfig;
use dgstereo_data::synthetic::TexturePreset;
use serde::{Deserialize, Serialize};

/// The recipe of RAFT-Stereo and the paper; every value a key of the `[train]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainingConfig {
    /// Optimiser steps.
    pub steps: usize,
    /// Pairs per step.
    pub batch_size: usize,
    /// Crop `[height, width]`.
    pub crop: [usize; 2],
    /// Update iterations during training (all of them are supervised).
    pub iters: usize,
    /// Peak learning rate of the one-cycle schedule.
    pub lr: f64,
    /// AdamW weight decay (decoupled).
    pub weight_decay: f64,
    /// AdamW epsilon.
    pub eps: f64,
    /// AdamW `[beta1, beta2]` (PyTorch's defaults).
    pub betas: [f64; 2],
    /// Global gradient-norm clip (`clip_grad_norm_`); 0 disables clipping.
    pub clip: f64,
    /// Fraction of the schedule spent warming up (`pct_start`).
    pub warmup_fraction: f64,
    /// Schedule length beyond `steps` (`total_steps = steps + schedule_extra_steps`).
    pub schedule_extra_steps: usize,
    /// Seed of every random choice of the run (weights, data, augmentation).
    pub seed: u64,
    /// Steps between two log lines (JSONL and progress bar).
    pub log_every: usize,
    /// Steps between two checkpoints (a checkpoint is also written at the end); 0: end only.
    pub checkpoint_every: usize,
    /// Checkpoints kept on disk (the newest ones); at least 1.
    pub keep_checkpoints: usize,
    /// Steps between two validations (also run at the end); 0: never.
    pub validate_every: usize,
    /// Weights to start from instead of a random initialisation (RAFT-Stereo's `restore_ckpt`):
    /// an official `.pth`, a dgstereo `.safetensors` model or training checkpoint. Only the
    /// weights are taken; the optimiser, schedule and step start afresh (use `--resume` to
    /// continue a run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init: Option<PathBuf>,
    /// With `init`: every parameter must be in the file with its shape (`true`), or parameters
    /// it lacks or holds in another shape keep their random initialisation (`false`: e.g. the
    /// fusion and guidance modules, and the motion encoder's last convolution whose input grows
    /// with guidance, when the paper's model starts from RAFT-Stereo weights). Keys the model
    /// lacks are always an error.
    pub init_strict: bool,
    /// Decay of an exponential moving average of the weights ([`crate::ema`]), in `[0, 1)`;
    /// absent: no average. When set, validation, the checkpoints' model weights and the final
    /// `model.safetensors` are the average (e.g. 0.999: about the last thousand steps).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ema_decay: Option<f64>,
}

impl Default for TrainingConfig {
    fn default() -> Self {
        Self {
            steps: 200_000,
            batch_size: 4,
            crop: [320, 720],
            iters: 22,
            lr: 2e-4,
            weight_decay: 1e-5,
            eps: 1e-8,
            betas: [0.9, 0.999],
            clip: 1.0,
            warmup_fraction: 0.01,
            schedule_extra_steps: 100,
            seed: 1234,
            log_every: 10,
            checkpoint_every: 5000,
            keep_checkpoints: 3,
            validate_every: 5000,
            init: None,
            init_strict: true,
            ema_decay: None,
        }
    }
}

impl TrainingConfig {
    /// Checks the values; the message names the key.
    pub fn validate(&self) -> Result<()> {
        let err = |m: String| Err(Error::Config(m));
        if self.steps == 0 {
            return err("train.steps must be at least 1".into());
        }
        if self.batch_size == 0 {
            return err("train.batch_size must be at least 1".into());
        }
        if self.crop.contains(&0) {
            return err(format!("train.crop = {:?}: both sides must be positive", self.crop));
        }
        if self.iters == 0 {
            return err("train.iters must be at least 1".into());
        }
        for (key, v) in [("lr", self.lr), ("eps", self.eps)] {
            if !(v.is_finite() && v > 0.0) {
                return err(format!("train.{key} = {v}: must be a finite value > 0"));
            }
        }
        for (key, v) in [("weight_decay", self.weight_decay), ("clip", self.clip)] {
            if !(v.is_finite() && v >= 0.0) {
                return err(format!("train.{key} = {v}: must be a finite value >= 0"));
            }
        }
        if !self.betas.iter().all(|b| (0.0..1.0).contains(b)) {
            return err(format!("train.betas = {:?}: each must lie in [0, 1)", self.betas));
        }
        if !(self.warmup_fraction > 0.0 && self.warmup_fraction < 1.0) {
            return err(format!("train.warmup_fraction = {}: must lie in (0, 1)", self.warmup_fraction));
        }
        if self.log_every == 0 {
            return err("train.log_every must be at least 1".into());
        }
        if self.keep_checkpoints == 0 {
            return err("train.keep_checkpoints must be at least 1".into());
        }
        if let Some(d) = self.ema_decay
            && !(d.is_finite() && (0.0..1.0).contains(&d))
        {
            return err(format!("train.ema_decay = {d}: must be a finite value in [0, 1)"));
        }
        Ok(())
    }

    /// The schedule's `total_steps`.
    pub fn schedule_total_steps(&self) -> usize {
        self.steps + self.schedule_extra_steps
    }
}

/// Where training pairs come from (the `[data]` table).
///
/// ```toml
/// [data]
/// augment = true
/// [[data.sources]]
/// kind = "synthetic"     # or "sceneflow", "middlebury", "eth3d", "kitti", "folder"
/// weight = 1.0           # share of the batch elements drawn from this source
/// width = 640
/// height = 384
/// textures = "smooth"    # or "rich": dead-leaves shapes, flat and low-contrast surfaces, shading
/// [data.validation]
/// count = 8              # held-out synthetic pairs (scene seeds 2^40 + i; training draws other seeds)
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainingDataConfig {
    /// The training sources, mixed by their weights.
    pub sources: Vec<DataSource>,
    /// RAFT-Stereo's augmentation (colour, eraser, scale, crop); off: a random crop only.
    pub augment: bool,
    /// `log2` range of the augmentation's scale (`spatial_scale`).
    pub spatial_scale: [f64; 2],
    /// Saturation range of the colour jitter (`saturation_range`).
    pub saturation_range: [f32; 2],
    /// The validation set.
    pub validation: ValidationConfig,
}

impl Default for TrainingDataConfig {
    fn default() -> Self {
        Self {
            sources: vec![DataSource::default()],
            augment: true,
            spatial_scale: [-0.2, 0.4],
            saturation_range: [0.0, 1.4],
            validation: ValidationConfig::default(),
        }
    }
}

impl TrainingDataConfig {
    /// Checks that the files the keys name are there: the photo folders of the synthetic sources
    /// and of the validation set. [`validate`](Self::validate) reads no files, so an experiment
    /// file checks on a machine that has not fetched the data; this runs where the data is opened.
    pub fn check_files(&self) -> Result<()> {
        for (i, s) in self.sources.iter().enumerate() {
            if let DataSource::Synthetic { photos: Some(p), .. } = s {
                p.check_folder(&format!("data.sources[{i}]"))?;
            }
        }
        if let Some(p) = &self.validation.photos {
            p.check_folder("data.validation")?;
        }
        Ok(())
    }

    /// Checks the values without reading files; the message names the key.
    pub fn validate(&self) -> Result<()> {
        if self.sources.is_empty() {
            return Err(Error::Config("data.sources is empty: give at least one training source".into()));
        }
        for (i, s) in self.sources.iter().enumerate() {
            let w = s.weight();
            if !(w.is_finite() && w >= 0.0) {
                return Err(Error::Config(format!("data.sources[{i}].weight = {w}: must be finite and >= 0")));
            }
            if let DataSource::Synthetic {
                width, height, count, max_disparity, min_disparity, lattices, photos, ..
            } = s
            {
                if let Some(p) = photos {
                    p.check(&format!("data.sources[{i}]"))?;
                }
                if let Some(p) = lattices.filter(|p| !(0.0..=1.0).contains(p)) {
                    return Err(Error::Config(format!("data.sources[{i}].lattices = {p}: must be a share in [0, 1]")));
                }
                if *width < 16 || *height < 16 {
                    return Err(Error::Config(format!(
                        "data.sources[{i}]: synthetic images of {width}x{height} are too small (at least 16x16)"
                    )));
                }
                check_disparities(*max_disparity, *min_disparity, *width, &format!("data.sources[{i}]"))?;
                if *count == Some(0) {
                    return Err(Error::Config(format!("data.sources[{i}].count must be at least 1")));
                }
            }
        }
        let v = &self.validation;
        check_disparities(v.max_disparity, v.min_disparity, v.width, "data.validation")?;
        if let Some(p) = &v.photos {
            p.check("data.validation")?;
        }
        if self.sources.iter().map(DataSource::weight).sum::<f64>() <= 0.0 {
            return Err(Error::Config("data.sources: the weights sum to 0".into()));
        }
        if self.spatial_scale[0] > self.spatial_scale[1] {
            return Err(Error::Config(format!("data.spatial_scale = {:?}: expected [min, max]", self.spatial_scale)));
        }
        Ok(())
    }
}

/// The disparity keys of a synthetic source or the validation set (`table`): `max_disparity`
/// finite and > 1 (default `0.15 · width`), `min_disparity` `[lo, hi]` with
/// `0 < lo <= hi < max_disparity - 1`.
fn check_disparities(max: Option<f64>, min: Option<[f64; 2]>, width: usize, table: &str) -> Result<()> {
    if let Some(m) = max.filter(|m| !(m.is_finite() && *m > 1.0)) {
        return Err(Error::Config(format!("{table}.max_disparity = {m}: must be a finite value > 1")));
    }
    let max = max.unwrap_or(0.15 * width as f64);
    match min {
        Some([lo, hi]) if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi && hi < max - 1.0) => {
            Err(Error::Config(format!(
                "{table}.min_disparity = [{lo}, {hi}]: expected [lo, hi] with 0 < lo <= hi < max_disparity - 1 ({})",
                max - 1.0
            )))
        }
        _ => Ok(()),
    }
}

fn one() -> f64 {
    1.0
}
fn default_width() -> usize {
    640
}
fn default_height() -> usize {
    384
}

/// One source of training pairs (an entry of `[[data.sources]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum DataSource {
    /// The procedural generator of the data crate (exact ground truth, unlimited pairs).
    Synthetic {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// Image width.
        #[serde(default = "default_width")]
        width: usize,
        /// Image height.
        #[serde(default = "default_height")]
        height: usize,
        /// Largest disparity; default `0.15 · width`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max_disparity: Option<f64>,
        /// A fixed set of this many scenes; unlimited (a new scene per draw) when absent.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        count: Option<usize>,
        /// Texture mix: `"smooth"` (default: full-contrast gratings on every surface, the original
        /// generator) or `"rich"` (adds dead-leaves shapes with sharp edges, flat and low-contrast
        /// surfaces, and shading; `SyntheticConfig::rich` of the data crate).
        #[serde(default, skip_serializing_if = "is_smooth", deserialize_with = "texture_preset")]
        textures: TexturePreset,
        /// `[lo, hi]`: each scene draws its smallest disparity from this range (scenes whose far
        /// end is near, with wide bands at the left border that the right view cannot see);
        /// default: every scene's far end is at disparity 1.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        min_disparity: Option<[f64; 2]>,
        /// Share of scenes with a lattice in front (a trellis or fence: thin bars, a repetitive
        /// pattern, the scene seen through its holes), in [0, 1]; default 0.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        lattices: Option<f64>,
        /// Surfaces textured with crops of real photographs (`{ dir = "...", share = 0.5 }`);
        /// default: procedural textures only.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        photos: Option<PhotoTextures>,
    },
    /// SceneFlow (`root` holds `frames_*pass` and `disparity`).
    Sceneflow {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
        /// `flyingthings` (TRAIN), `driving` or `monkaa`.
        #[serde(default = "default_subset")]
        subset: String,
        /// `clean` or `final`.
        #[serde(default = "default_pass")]
        pass: String,
    },
    /// Middlebury 2014 (`root` holds the scene folders).
    Middlebury {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
    },
    /// ETH3D two-view training set.
    Eth3d {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
    },
    /// KITTI 2012 or 2015 (`root` is the `training` folder).
    Kitti {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
        /// 2012 or 2015.
        #[serde(default = "default_kitti")]
        version: u32,
    },
    /// A folder of pairs with ground truth beside them (see the data crate's `folder_pairs`).
    Folder {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The folder.
        root: PathBuf,
        /// Ground truth with holes (LiDAR, KITTI-style PNGs): augment with the sparse augmentor.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        sparse: bool,
    },
}

fn is_smooth(t: &TexturePreset) -> bool {
    *t == TexturePreset::Smooth
}

/// Reads `textures`, naming the key in the error (an internally tagged enum's errors otherwise
/// only point at the table).
fn texture_preset<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<TexturePreset, D::Error> {
    use serde::de::{Error as _, IntoDeserializer, value};
    let name = String::deserialize(d).map_err(|e| D::Error::custom(format!("textures: {e}")))?;
    TexturePreset::deserialize(IntoDeserializer::<value::Error>::into_deserializer(name.as_str()))
        .map_err(|e| D::Error::custom(format!("textures = \"{name}\": {e}")))
}

fn default_subset() -> String {
    "flyingthings".into()
}
fn default_pass() -> String {
    "clean".into()
}
fn default_kitti() -> u32 {
    2015
}

impl DataSource {
    /// Whether the ground truth has holes, so augmentation must move valid points rather than
    /// interpolate (RAFT-Stereo's `sparse=True` sets: KITTI, ETH3D, Middlebury; a folder when it
    /// says so).
    pub fn sparse_ground_truth(&self) -> bool {
        match self {
            Self::Synthetic { .. } | Self::Sceneflow { .. } => false,
            Self::Middlebury { .. } | Self::Eth3d { .. } | Self::Kitti { .. } => true,
            Self::Folder { sparse, .. } => *sparse,
        }
    }
}

impl Default for DataSource {
    fn default() -> Self {
        Self::Synthetic {
            weight: 1.0,
            width: default_width(),
            height: default_height(),
            max_disparity: None,
            count: None,
            textures: TexturePreset::Smooth,
            min_disparity: None,
            lattices: None,
            photos: None,
        }
    }
}

/// Photo textures of a synthetic source or the validation set (`photos = { dir, share }`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotoTextures {
    /// The folder of photographs (`scripts/fetch-photo-textures.sh` fills `data/photos/train` and
    /// `data/photos/held-out`).
    pub dir: PathBuf,
    /// Share of the surfaces (and backgrounds) textured with a photograph, in (0, 1].
    pub share: f64,
}

impl PhotoTextures {
    /// Checks the share; `key` names the table.
    fn check(&self, key: &str) -> Result<()> {
        if !(self.share > 0.0 && self.share <= 1.0) {
            return Err(Error::Config(format!("{key}.photos.share = {}: must be a share in (0, 1]", self.share)));
        }
        Ok(())
    }

    /// Checks that the folder's photographs load (they are decoded once per process, so the
    /// generator later finds them cached); `key` names the table.
    pub(crate) fn check_folder(&self, key: &str) -> Result<()> {
        dgstereo_data::synthetic::PhotoLibrary::of_folder(&self.dir)
            .map(|_| ())
            .map_err(|e| Error::Config(format!("{key}.photos.dir: {e}")))
    }
}

impl DataSource {
    /// The source's share of the batch.
    pub fn weight(&self) -> f64 {
        match self {
            Self::Synthetic { weight, .. }
            | Self::Sceneflow { weight, .. }
            | Self::Middlebury { weight, .. }
            | Self::Eth3d { weight, .. }
            | Self::Kitti { weight, .. }
            | Self::Folder { weight, .. } => *weight,
        }
    }
}

/// The validation set (`[data.validation]`): held-out synthetic pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidationConfig {
    /// Number of pairs (0: no validation).
    pub count: usize,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Seed of the first pair; pair `i` is the scene of `seed + i`.
    pub seed: u64,
    /// Update iterations at validation (`valid_iters`).
    pub iters: usize,
    /// Texture mix of the pairs, as a synthetic source's `textures` (default `"smooth"`, which
    /// keeps validation numbers comparable with earlier runs).
    #[serde(skip_serializing_if = "is_smooth", deserialize_with = "texture_preset")]
    pub textures: TexturePreset,
    /// Largest disparity, as a synthetic source's `max_disparity` (default `0.15 · width`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_disparity: Option<f64>,
    /// Range of each scene's smallest disparity, as a synthetic source's `min_disparity`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_disparity: Option<[f64; 2]>,
    /// Photo textures of the pairs, as a synthetic source's `photos` (a held-out set rendered
    /// with photographs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub photos: Option<PhotoTextures>,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        Self {
            count: 8,
            width: 640,
            height: 384,
            seed: 1 << 40,
            iters: 32,
            textures: TexturePreset::Smooth,
            max_disparity: None,
            min_disparity: None,
            photos: None,
        }
    }
}

impl ValidationConfig {
    /// The generator's settings for the validation pairs.
    pub fn synthetic(&self) -> SyntheticConfig {
        let mut config =
            synthetic_config([self.width, self.height], self.textures, self.max_disparity, self.min_disparity, None);
        with_photos(&mut config, self.photos.as_ref());
        config
    }
}

/// The generator's settings from a synthetic source's (or the validation set's) keys: the
/// default scene mix at `[width, height]`, the texture preset, the disparity range and the share
/// of scenes with a lattice.
pub(crate) fn synthetic_config(
    [width, height]: [usize; 2],
    textures: TexturePreset,
    max_disparity: Option<f64>,
    min_disparity: Option<[f64; 2]>,
    lattices: Option<f64>,
) -> SyntheticConfig {
    let mut config = SyntheticConfig::with_size(width, height).with_textures(textures);
    if let Some(m) = max_disparity {
        config.max_disparity = m;
    }
    config.min_disparity_range = min_disparity;
    config.lattice_prob = lattices.unwrap_or(0.0);
    config
}

/// `config` with the photo textures of `photos` (unchanged without).
pub(crate) fn with_photos(config: &mut SyntheticConfig, photos: Option<&PhotoTextures>) {
    if let Some(p) = photos {
        config.photo_dir = Some(p.dir.clone());
        config.photo_prob = p.share;
    }
}
