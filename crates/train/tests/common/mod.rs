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

/// Whether the tensors of `a` and `b` under the module path `prefix` are bit-identical (at least
/// one tensor lies there).
pub fn identical_under(a: &[(String, Vec<f32>)], b: &[(String, Vec<f32>)], prefix: &str) -> bool {
    let pick = |w: &[(String, Vec<f32>)]| -> Vec<(String, Vec<u32>)> {
        w.iter()
            .filter(|(n, _)| n.starts_with(prefix))
            .map(|(n, v)| (n.clone(), v.iter().map(|x| x.to_bits()).collect()))
            .collect()
    };
    let (a, b) = (pick(a), pick(b));
    assert!(!a.is_empty(), "no parameter under {prefix}");
    a == b
}

/// Trains `parts` (3 steps, a checkpoint each) under `dir` twice, once through and once stopped
/// after step 2 and resumed; asserts that the checkpoints are written atomically (no temporary
/// file beside them) and that both runs' final weights are bit-identical; returns them.
pub fn resumed_run_matches_uninterrupted(
    mut parts: TrainParts,
    device: &burn::tensor::Device,
    dir: &std::path::Path,
) -> Vec<(String, Vec<f32>)> {
    use std::path::Path;

    use dgstereo_train::checkpoint::{list_checkpoints, load_checkpoint};
    use dgstereo_train::run::{RunOptions, checkpoint_dir, train};

    assert_eq!(parts.train.steps, 3, "the check stops after step 2 of 3");
    parts.train.checkpoint_every = 1;
    let (full, split) = (dir.join("full"), dir.join("split"));
    let options = |out: &Path, resume: bool, stop_after: Option<usize>| RunOptions {
        out: out.to_path_buf(),
        resume,
        stop_after,
        progress: None,
        notice: |_| {},
        stop: None,
    };
    assert!(train(parts.clone(), device, &options(&full, false, None)).unwrap().finished);
    let first = train(parts.clone(), device, &options(&split, false, Some(2))).unwrap();
    assert_eq!((first.finished, first.steps), (false, 2));
    let names: Vec<String> = std::fs::read_dir(checkpoint_dir(&split))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| n.ends_with(".safetensors")), "{names:?}");
    assert!(train(parts.clone(), device, &options(&split, true, None)).unwrap().finished);
    let newest = |out: &Path| {
        let (step, path) = list_checkpoints(&checkpoint_dir(out)).unwrap().pop().unwrap();
        assert_eq!(step, 3);
        load_checkpoint(parts.clone(), &path, device).unwrap()
    };
    let (a, b) = (weights(&newest(&full).inference_model()), weights(&newest(&split).inference_model()));
    assert!(identical_under(&a, &b, ""), "the resumed run differs from the uninterrupted one");
    a
}
