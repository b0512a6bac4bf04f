//! A tiny run configuration shared by the training tests.

#![allow(dead_code)]

use dgstereo_experiment::{DataSource, SyntheticScenes, TrainingConfig, TrainingDataConfig, ValidationConfig};
use dgstereo_loss::LossConfig;
use dgstereo_model::{ModelConfig, RaftStereo};
use dgstereo_prior::PriorConfig;
use dgstereo_train::TrainParts;

/// Image size of the tests: `[height, width]`.
pub const SIZE: [usize; 2] = [32, 64];

/// A small network: narrow GRUs and matching features, RAFT-Stereo's structure otherwise.
pub fn tiny_model() -> ModelConfig {
    let mut m = ModelConfig::default();
    m.updater.hidden_dims = [32, 32, 32];
    m.updater.n_gru_layers = 2;
    m.encoder.feature_dim = 64;
    m.correlation.levels = 2;
    m
}

/// A run on synthetic 48x96 pairs without augmentation; `count` scenes (None: a new one per draw).
pub fn tiny_parts(steps: usize, iters: usize, lr: f64, count: Option<usize>, batch_size: usize) -> TrainParts {
    let train = TrainingConfig {
        steps,
        batch_size,
        crop: SIZE,
        iters,
        lr,
        seed: 7,
        log_every: 5,
        checkpoint_every: 0,
        validate_every: 0,
        ..TrainingConfig::default()
    };
    let data = TrainingDataConfig {
        sources: vec![DataSource::Synthetic {
            weight: 1.0,
            scenes: SyntheticScenes { width: SIZE[1], height: SIZE[0], max_disparity: Some(5.0), ..Default::default() },
            count,
            lattices: None,
        }],
        augment: false,
        validation: ValidationConfig { count: 0, ..ValidationConfig::default() },
        ..TrainingDataConfig::default()
    };
    TrainParts {
        name: "tiny".into(),
        model: tiny_model(),
        prior: PriorConfig::None {},
        loss: LossConfig::default(),
        train,
        data,
        resolved_toml: "# tiny test run\n".into(),
    }
}

/// Every tensor of `model` by module path, as `f32` values.
pub fn weights(model: &RaftStereo) -> Vec<(String, Vec<f32>)> {
    use burn::store::ModuleSnapshot;
    model
        .collect(None, None, true)
        .into_iter()
        .map(|t| {
            let data = burn::store::bridge::to_data(&t).unwrap();
            (t.name.clone(), data.convert::<f32>().try_to_vec::<f32>().unwrap())
        })
        .collect()
}
