//! [`TrainingConfig`]: the optimisation recipe, the `[train]` table.

use std::path::PathBuf;

use dgstereo_core::{Problem, Result};
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
    /// Depth Anything V2 weights loaded into the model's monocular network before `init`
    /// (DEFOM-Stereo's `depth_anything_v2_vit{s,l}.pth`): an official Depth Anything V2 `.pth`
    /// or a catalog name (`depth-anything-v2-small`). Non-strict as the official code: the ViT
    /// (`pretrained.*`) and depth head (`depth_head.*`) come from the file, the feature trunk,
    /// which the file lacks, keeps its initialisation, and keys the network lacks are ignored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub monocular_init: Option<PathBuf>,
    /// timm's ImageNet `mobilenetv2_100` weights loaded into IGEV-Stereo's MobileNetV2 feature
    /// trunk before `init` (the official `Feature`'s `pretrained=True`): a state dict in timm
    /// 0.5.4's layout (`conv_stem`, `bn1`, `blocks.*`), `.pth` or `.safetensors`. Every tensor
    /// of the trunk must be in the file; its head and last stage are ignored, the decoder keeps
    /// its initialisation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub feature_init: Option<PathBuf>,
    /// Module paths whose parameters do not train (no gradient, never changed by the
    /// optimiser, its weight decay included): each entry is a path prefix such as
    /// `monocular.pretrained`, and must name at least one parameter of the model.
    /// DEFOM-Stereo freezes `monocular.pretrained` and `monocular.depth_head`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub frozen: Vec<String>,
    /// Decay of an exponential moving average of the weights (the trainer's `ema`), in `[0, 1)`;
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
            monocular_init: None,
            feature_init: None,
            frozen: Vec::new(),
            ema_decay: None,
        }
    }
}

impl TrainingConfig {
    /// Everything wrong with the values, keys relative to the `[train]` table (`steps`, `lr`).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        let mut add = |key: &str, reason: String| problems.push(Problem::new(key, reason));
        for (key, v) in [("steps", self.steps), ("batch_size", self.batch_size), ("iters", self.iters)] {
            if v == 0 {
                add(key, "must be at least 1".into());
            }
        }
        if self.crop.contains(&0) {
            add("crop", format!("{:?}: both sides must be positive", self.crop));
        }
        for (key, v) in [("lr", self.lr), ("eps", self.eps)] {
            if !(v.is_finite() && v > 0.0) {
                add(key, format!("{v}: must be a finite value > 0"));
            }
        }
        for (key, v) in [("weight_decay", self.weight_decay), ("clip", self.clip)] {
            if !(v.is_finite() && v >= 0.0) {
                add(key, format!("{v}: must be a finite value >= 0"));
            }
        }
        if !self.betas.iter().all(|b| (0.0..1.0).contains(b)) {
            add("betas", format!("{:?}: each must lie in [0, 1)", self.betas));
        }
        if !(self.warmup_fraction > 0.0 && self.warmup_fraction < 1.0) {
            add("warmup_fraction", format!("{}: must lie in (0, 1)", self.warmup_fraction));
        }
        for (key, v) in [("log_every", self.log_every), ("keep_checkpoints", self.keep_checkpoints)] {
            if v == 0 {
                add(key, "must be at least 1".into());
            }
        }
        for (i, prefix) in self.frozen.iter().enumerate() {
            let bad = prefix.is_empty() || prefix.split('.').any(str::is_empty);
            if bad {
                add(
                    &format!("frozen[{i}]"),
                    format!("'{prefix}' is not a module path (dotted names, e.g. monocular.pretrained)"),
                );
            }
        }
        if let Some(d) = self.ema_decay
            && !(d.is_finite() && (0.0..1.0).contains(&d))
        {
            add("ema_decay", format!("{d}: must be a finite value in [0, 1)"));
        }
        problems
    }

    /// Checks the values.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] with the first of [`problems`](Self::problems), its key
    /// as an experiment file writes it (`train.steps`).
    pub fn validate(&self) -> Result<()> {
        Problem::first(self.problems()).map_err(|e| e.within("train"))
    }

    /// The schedule's `total_steps`.
    pub fn schedule_total_steps(&self) -> usize {
        self.steps + self.schedule_extra_steps
    }
}
