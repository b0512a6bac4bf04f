//! [`TrainingConfig`] (the `[train]` table) and [`TrainingDataConfig`] (the `[data]` table).

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
    /// Update iterations during training.
    pub iters: usize,
    /// Peak learning rate of the one-cycle schedule.
    pub lr: f64,
    /// AdamW weight decay.
    pub weight_decay: f64,
    /// AdamW epsilon.
    pub eps: f64,
    /// Global gradient-norm clip.
    pub clip: f64,
    /// Seed of every random choice of the run.
    pub seed: u64,
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
            clip: 1.0,
            seed: 1234,
        }
    }
}

/// Where training pairs come from (the `[data]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct TrainingDataConfig {}
