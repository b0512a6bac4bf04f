//! `train.ema_decay`: the moving average of the weights follows its recurrence, is what
//! checkpoints ship as model weights, and resumes exactly.

mod common;

use std::path::Path;

use dgstereo_core::default_device;
use dgstereo_experiment::{SyntheticScenes, TrainingConfig, ValidationConfig};
use dgstereo_model::RaftStereo;
use dgstereo_train::checkpoint::{list_checkpoints, load_checkpoint, read_metadata, save_checkpoint};
use dgstereo_train::ema::{RAW_WEIGHTS_PREFIX, warmed_decay};
use dgstereo_train::run::{RunOptions, checkpoint_dir, train};
use dgstereo_train::trainer::init_model;
use dgstereo_train::{TrainParts, Trainer};

/// Every float tensor of `model` by module path, as `f64`.
fn weights(model: &RaftStereo) -> Vec<(String, Vec<f64>)> {
    use burn::store::ModuleSnapshot;
    let mut out: Vec<(String, Vec<f64>)> = model
        .collect(None, None, true)
        .into_iter()
        .filter_map(|t| {
            let data = burn::store::bridge::to_data(&t).unwrap();
            data.dtype().is_float().then(|| {
                (
                    t.name.clone(),
                    data.convert::<f32>().try_to_vec::<f32>().unwrap().into_iter().map(f64::from).collect(),
                )
            })
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

fn max_diff(a: &[(String, Vec<f64>)], b: &[(String, Vec<f64>)]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut worst = 0f64;
    for ((na, va), (nb, vb)) in a.iter().zip(b) {
        assert_eq!(na, nb);
        assert_eq!(va.len(), vb.len(), "{na}");
        for (x, y) in va.iter().zip(vb) {
            worst = worst.max((x - y).abs());
        }
    }
    worst
}

/// The tiny run of the other tests with a moving average of decay `decay`.
fn ema_parts(steps: usize, decay: f64) -> TrainParts {
    let mut parts = common::tiny_parts(steps, 1, 5e-3, Some(2), 1);
    parts.train.ema_decay = Some(decay);
    parts
}

fn opts(out: &Path, resume: bool, stop_after: Option<usize>) -> RunOptions {
    RunOptions { out: out.to_path_buf(), resume, stop_after, progress: None, notice: |_| {}, stop: None }
}

fn newest_checkpoint(out: &Path) -> std::path::PathBuf {
    list_checkpoints(&checkpoint_dir(out)).unwrap().pop().unwrap().1
}

#[test]
fn ema_decay_must_be_finite_and_in_zero_one() {
    let with = |d: f64| TrainingConfig { ema_decay: Some(d), ..TrainingConfig::default() }.validate();
    for bad in [1.0, -0.1, f64::NAN, f64::INFINITY, 1.5] {
        let e = with(bad).expect_err("refused").to_string();
        assert!(e.contains("train.ema_decay") && e.contains(&bad.to_string()), "{e}");
    }
    for good in [0.0, 0.5, 0.999, 0.9999] {
        with(good).unwrap();
    }
    // The key reads from TOML; absent it is off and is not written back.
    let t: TrainingConfig = toml::from_str("ema_decay = 0.999").unwrap();
    assert_eq!(t.ema_decay, Some(0.999));
    let t: TrainingConfig = toml::from_str("ema_decay = nan").unwrap();
    let message = t.validate().unwrap_err().to_string();
    assert!(message.contains("ema_decay") && message.contains("NaN"), "{message}");
    let off: TrainingConfig = toml::from_str("").unwrap();
    assert_eq!(off.ema_decay, None);
    assert!(!toml::to_string(&off).unwrap().contains("ema_decay"));
    // A misspelt key is still refused.
    assert!(toml::from_str::<TrainingConfig>("ema_dacay = 0.9").unwrap_err().to_string().contains("ema_dacay"));
    // The run refuses it before doing anything.
    let e = Trainer::new(ema_parts(2, 1.0), &default_device()).err().expect("refused").to_string();
    assert!(e.contains("train.ema_decay"), "{e}");
}

#[test]
fn warm_up_caps_the_decay_early_on() {
    assert_eq!(warmed_decay(0.999, 1), 2.0 / 11.0);
    assert_eq!(warmed_decay(0.999, 100), 101.0 / 110.0);
    assert_eq!(warmed_decay(0.5, 100), 0.5);
    assert_eq!(warmed_decay(0.0, 1), 0.0);
}

#[test]
fn ema_follows_the_recurrence_of_the_weight_snapshots() {
    let device = default_device();
    // 0.2 lies between the warm-up's 2/11 (step 1) and 3/12 (step 2): both branches of the min.
    let decay = 0.2;
    let mut trainer = Trainer::new(ema_parts(4, decay), &device).unwrap();
    let start = weights(&trainer.inference_model());
    assert_eq!(max_diff(&weights(&trainer.shipped_model()), &start), 0.0, "the average starts at the weights");
    let mut expected = start.clone();
    for _ in 0..4 {
        trainer.step().unwrap();
        let d = warmed_decay(decay, trainer.completed_steps());
        let w = weights(&trainer.inference_model());
        for ((_, e), (_, w)) in expected.iter_mut().zip(&w) {
            for (e, w) in e.iter_mut().zip(w) {
                *e = d * *e + (1.0 - d) * w;
            }
        }
    }
    let trained = weights(&trainer.inference_model());
    let average = weights(&trainer.shipped_model());
    let error = max_diff(&average, &expected);
    let spread = max_diff(&trained, &expected);
    eprintln!("max |ema - recurrence| = {error:e}, max |w - recurrence| = {spread:e}");
    assert!(spread > 1e-4, "the average must differ from the trained weights for the check to mean anything");
    assert!(error <= 1e-6, "the average is off its recurrence by {error}");
    assert!(max_diff(&trained, &start) > 1e-3, "the weights trained");

    // With decay 0 the average is the trained weights, exactly.
    let mut trainer = Trainer::new(ema_parts(2, 0.0), &device).unwrap();
    trainer.step().unwrap();
    trainer.step().unwrap();
    assert_eq!(max_diff(&weights(&trainer.shipped_model()), &weights(&trainer.inference_model())), 0.0);
}

#[test]
fn checkpoints_ship_the_average_and_resume_it_exactly() {
    let device = default_device();
    let mut parts = ema_parts(4, 0.5);
    // One small validation pair at the end, to see which weights it scores.
    parts.data.validation = ValidationConfig {
        count: 1,
        iters: 1,
        scenes: SyntheticScenes { width: 64, height: 32, ..Default::default() },
        ..Default::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let (full, split) = (dir.path().join("full"), dir.path().join("split"));
    assert!(train(parts.clone(), &device, &opts(&full, false, None)).unwrap().finished);
    train(parts.clone(), &device, &opts(&split, false, Some(2))).unwrap();
    assert!(train(parts.clone(), &device, &opts(&split, true, None)).unwrap().finished);

    let load = |out: &Path| load_checkpoint(parts.clone(), &newest_checkpoint(out), &device).unwrap();
    let (a, b) = (load(&full), load(&split));
    assert_eq!((a.completed_steps(), b.completed_steps()), (4, 4));
    let raw_diff = max_diff(&weights(&a.inference_model()), &weights(&b.inference_model()));
    let ema_diff = max_diff(&weights(&a.shipped_model()), &weights(&b.shipped_model()));
    eprintln!("resumed vs uninterrupted: raw {raw_diff:e}, ema {ema_diff:e}");
    assert!(raw_diff <= 1e-6 && ema_diff <= 1e-6, "raw {raw_diff}, ema {ema_diff}");
    // The average is not the trained weights, so restoring both is not one check twice.
    let (raw, average) = (weights(&a.inference_model()), weights(&a.shipped_model()));
    assert!(max_diff(&raw, &average) > 1e-4);

    // Read as plain weights (as `infer --weights` does), a checkpoint and the final model are the average.
    let newest = newest_checkpoint(&full);
    let as_weights =
        dgstereo_model::checkpoint::load_safetensors(init_model(&parts.model, &device, None).unwrap(), &newest)
            .unwrap();
    assert_eq!(max_diff(&weights(&as_weights), &average), 0.0);
    let fin = dgstereo_model::checkpoint::load_safetensors(
        init_model(&parts.model, &device, None).unwrap(),
        &full.join("model.safetensors"),
    )
    .unwrap();
    assert_eq!(max_diff(&weights(&fin), &average), 0.0);
    assert_eq!(read_metadata(&newest).unwrap().get("ema_decay").map(String::as_str), Some("0.5"));
    // Every model tensor has its raw counterpart under the training-state prefix.
    let bytes = std::fs::read(&newest).unwrap();
    let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut model_keys: Vec<&str> =
        file.names().into_iter().map(String::as_str).filter(|n| !n.starts_with("__train__.")).collect();
    let mut raw_keys: Vec<&str> = file.names().into_iter().filter_map(|n| n.strip_prefix(RAW_WEIGHTS_PREFIX)).collect();
    model_keys.sort();
    raw_keys.sort();
    assert!(!raw_keys.is_empty());
    assert_eq!(raw_keys, model_keys);

    // Validation scored the average and says so.
    let log = std::fs::read_to_string(full.join("log.jsonl")).unwrap();
    let validations: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|v: &serde_json::Value| v["kind"] == "validation")
        .collect();
    assert!(!validations.is_empty() && validations.iter().all(|v| v["weights"] == "ema"), "{log}");
}

#[test]
fn checkpoints_with_and_without_ema_load_either_way() {
    let device = default_device();
    let dir = tempfile::tempdir().unwrap();
    // A checkpoint of a run without EMA: the average starts at its weights.
    let mut plain = common::tiny_parts(4, 1, 5e-3, Some(1), 1);
    let mut trainer = Trainer::new(plain.clone(), &device).unwrap();
    trainer.step().unwrap();
    let old = save_checkpoint(&trainer, &dir.path().join("plain"), 3).unwrap();
    let saved = weights(&trainer.inference_model());
    plain.train.ema_decay = Some(0.9);
    let resumed = load_checkpoint(plain.clone(), &old, &device).unwrap();
    assert_eq!(max_diff(&weights(&resumed.inference_model()), &saved), 0.0);
    assert_eq!(max_diff(&weights(&resumed.shipped_model()), &saved), 0.0);

    // A checkpoint of a run with EMA resumed without it: the raw weights, not the average.
    let mut trainer = Trainer::new(plain.clone(), &device).unwrap();
    trainer.step().unwrap();
    trainer.step().unwrap();
    let with_ema = save_checkpoint(&trainer, &dir.path().join("ema"), 3).unwrap();
    let raw = weights(&trainer.inference_model());
    assert!(max_diff(&raw, &weights(&trainer.shipped_model())) > 1e-4);
    plain.train.ema_decay = None;
    let resumed = load_checkpoint(plain, &with_ema, &device).unwrap();
    assert!(resumed.moving_average_decay().is_none());
    assert_eq!(max_diff(&weights(&resumed.inference_model()), &raw), 0.0);
}
