//! Checkpoints: a stopped and resumed run equals an uninterrupted one; writes are atomic.

mod common;

use std::path::Path;

use dgstereo_core::default_device;
use dgstereo_train::Trainer;
use dgstereo_train::checkpoint::{list_checkpoints, load_checkpoint, save_checkpoint, write_atomic};
use dgstereo_train::run::{RunOptions, checkpoint_dir, train};
use dgstereo_train::trainer::init_model;

fn max_diff(a: &[(String, Vec<f32>)], b: &[(String, Vec<f32>)]) -> f32 {
    assert_eq!(a.len(), b.len());
    let mut worst = 0f32;
    for ((na, va), (nb, vb)) in a.iter().zip(b) {
        assert_eq!(na, nb);
        for (x, y) in va.iter().zip(vb) {
            worst = worst.max((x - y).abs());
        }
    }
    worst
}

fn opts(out: &Path, resume: bool, stop_after: Option<usize>) -> RunOptions {
    RunOptions { out: out.to_path_buf(), resume, stop_after, progress: None, notice: |_| {}, stop: None }
}

#[test]
fn stopped_and_resumed_run_equals_uninterrupted_run() {
    let device = default_device();
    let parts = common::tiny_parts(6, 2, 5e-3, None, 2);
    let dir = tempfile::tempdir().unwrap();
    let (full, split) = (dir.path().join("full"), dir.path().join("split"));

    let done = train(parts.clone(), &device, &opts(&full, false, None)).unwrap();
    assert!(done.finished && done.steps == 6);

    let first = train(parts.clone(), &device, &opts(&split, false, Some(3))).unwrap();
    assert!(!first.finished && first.steps == 3);
    assert_eq!(list_checkpoints(&checkpoint_dir(&split)).unwrap().last().unwrap().0, 3);
    // A fresh run refuses a folder with checkpoints.
    assert!(train(parts.clone(), &device, &opts(&split, false, None)).is_err());
    let second = train(parts.clone(), &device, &opts(&split, true, None)).unwrap();
    assert!(second.finished && second.steps == 6);

    let load = |out: &Path| {
        let (_, path) = list_checkpoints(&checkpoint_dir(out)).unwrap().pop().unwrap();
        load_checkpoint(parts.clone(), &path, &device).unwrap()
    };
    let (a, b) = (load(&full), load(&split));
    assert_eq!((a.completed_steps(), b.completed_steps()), (6, 6));
    let diff = max_diff(&common::weights(&a.inference_model()), &common::weights(&b.inference_model()));
    eprintln!("max |w_resumed - w_uninterrupted| = {diff:e}");
    assert!(diff <= 1e-6, "resumed weights differ by {diff}");
    // A training checkpoint also loads as plain weights (its optimiser state is skipped).
    let (_, newest) = list_checkpoints(&checkpoint_dir(&full)).unwrap().pop().unwrap();
    let as_weights =
        dgstereo_model::checkpoint::load_safetensors(init_model(&parts.model, &device, None).unwrap(), &newest)
            .unwrap();
    assert_eq!(max_diff(&common::weights(&as_weights), &common::weights(&a.inference_model())), 0.0);
    // The weights did change over training, so equality is not trivial.
    let fresh = Trainer::new(parts.clone(), &device).unwrap();
    assert!(max_diff(&common::weights(&fresh.inference_model()), &common::weights(&a.inference_model())) > 1e-4);
    // Every logged step of the uninterrupted run was logged identically by the split run.
    let train_lines = |out: &Path| -> Vec<serde_json::Value> {
        std::fs::read_to_string(out.join("log.jsonl"))
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter(|v| v["kind"] == "train")
            .collect()
    };
    let split_lines = train_lines(&split);
    for line in train_lines(&full) {
        let other = split_lines.iter().find(|v| v["step"] == line["step"]).expect("same logged steps");
        assert_eq!((&line["loss"], &line["epe"]), (&other["loss"], &other["epe"]));
    }
    assert!(full.join("model.safetensors").is_file() && full.join("summary.json").is_file());
}

#[test]
fn interrupted_write_leaves_previous_checkpoint_readable() {
    let device = default_device();
    let parts = common::tiny_parts(4, 1, 1e-3, Some(1), 1);
    let dir = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(parts.clone(), &device).unwrap();
    trainer.step().unwrap();
    let good = save_checkpoint(&trainer, dir.path(), 3).unwrap();
    let good_weights = common::weights(&trainer.inference_model());

    // A run killed between write and rename leaves a partial temporary file.
    trainer.step().unwrap();
    let bytes = dgstereo_train::checkpoint::checkpoint_bytes(&trainer).unwrap();
    let tmp = dir.path().join(".step-00000002.safetensors.tmp");
    std::fs::write(&tmp, &bytes[..bytes.len() / 2]).unwrap();
    // A failed write: the destination cannot be replaced (it is a non-empty folder).
    let blocked = dir.path().join("step-00000009.safetensors");
    std::fs::create_dir_all(blocked.join("x")).unwrap();
    assert!(write_atomic(&blocked, &bytes).is_err());
    assert!(!dir.path().join(".step-00000009.safetensors.tmp").exists(), "failed write leaves no temporary file");

    let listed = list_checkpoints(dir.path()).unwrap();
    assert_eq!(listed, vec![(1, good.clone())], "only complete checkpoints are listed");
    let restored = load_checkpoint(parts.clone(), &good, &device).unwrap();
    assert_eq!(restored.completed_steps(), 1);
    assert_eq!(max_diff(&common::weights(&restored.inference_model()), &good_weights), 0.0);
    // A truncated file under a checkpoint name is refused with a clear error, not a panic.
    let broken = dir.path().join("broken.safetensors");
    std::fs::write(&broken, &bytes[..100]).unwrap();
    let err = load_checkpoint(parts, &broken, &device).err().unwrap().to_string();
    assert!(err.contains("broken.safetensors"), "{err}");
}

#[test]
fn only_the_newest_checkpoints_are_kept() {
    let device = default_device();
    let mut parts = common::tiny_parts(5, 1, 1e-3, Some(1), 1);
    parts.train.checkpoint_every = 1;
    parts.train.keep_checkpoints = 2;
    let dir = tempfile::tempdir().unwrap();
    train(parts, &device, &opts(dir.path(), false, None)).unwrap();
    let steps: Vec<usize> = list_checkpoints(&checkpoint_dir(dir.path())).unwrap().into_iter().map(|c| c.0).collect();
    assert_eq!(steps, vec![4, 5]);
}

#[test]
fn non_finite_loss_stops_the_run_and_keeps_the_last_checkpoint() {
    let device = default_device();
    let mut parts = common::tiny_parts(6, 1, 1e-3, Some(1), 1);
    parts.train.checkpoint_every = 2;
    let dir = tempfile::tempdir().unwrap();
    train(parts.clone(), &device, &opts(dir.path(), false, Some(2))).unwrap();
    // An absurd learning rate makes the weights, and then the loss, non-finite.
    parts.train.lr = 1e30;
    let err = train(parts.clone(), &device, &opts(dir.path(), true, None)).expect_err("the run must stop").to_string();
    eprintln!("{err}");
    assert!(err.contains("not finite") || err.contains("loss is"), "{err}");
    assert!(err.contains("last good checkpoint"), "{err}");
    let kept = list_checkpoints(&checkpoint_dir(dir.path())).unwrap();
    assert!(!kept.is_empty());
    for (_, p) in kept {
        load_checkpoint(parts.clone(), &p, &device).expect("every kept checkpoint is readable and finite");
    }
}
