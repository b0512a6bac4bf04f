//! Four deliberate deviations from the official training loop (`train_stereo.py`) that the
//! training-step verification must catch; the CLI's `verify_train_step` test shows it passing.
//!
//! The reference is `../shared/golden/raft_stereo_random.train_step.safetensors` (see its README):
//! the default RAFT-Stereo from `raft_stereo_random.pth`, a batch of two 64x128 Cones crops, 4
//! iterations, two steps. Each test runs the two steps once, with the defaults as recipe (as the
//! experiment crate resolves an empty file) and one alteration; the failing checks are printed.

use std::path::PathBuf;

use dgstereo_core::default_device;
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_experiment::{TrainingConfig, TrainingDataConfig};
use dgstereo_loss::LossConfig;
use dgstereo_model::ModelConfig;
use dgstereo_prior::PriorConfig;
use dgstereo_train::TrainParts;
use dgstereo_train::verify_step::{Alteration, CheckKind, TrainStepReport, verify_train_step};

const REFERENCE: &str = "golden/raft_stereo_random.train_step.safetensors";

/// The recipe of an experiment file that sets nothing: every section's default.
fn default_recipe() -> TrainParts {
    TrainParts {
        name: "verify-train-step".into(),
        model: ModelConfig::default(),
        prior: PriorConfig::default(),
        loss: LossConfig::default(),
        train: TrainingConfig::default(),
        data: TrainingDataConfig::default(),
        resolved_toml: String::new(),
    }
}

fn run(test: &str, alteration: Alteration) -> Option<TrainStepReport> {
    let shared: PathBuf = shared_dir_for_test(test, REFERENCE)?;
    let weights = shared.join("golden/raft_stereo_random.pth");
    let report =
        verify_train_step(&weights, &shared.join(REFERENCE), &default_recipe(), Some(alteration), &default_device())
            .expect("the verification runs");
    Some(report)
}

/// The kinds of the failing checks; none of them may be a recipe line, since an alteration is
/// applied after the recipe is compared.
fn failing_kinds(report: &TrainStepReport) -> Vec<CheckKind> {
    for line in report.failures() {
        println!("failing: {} {}", line.key, line.text);
    }
    println!("{}", report.summary());
    let mut kinds: Vec<CheckKind> = report.failures().map(|l| l.kind).collect();
    kinds.dedup();
    assert!(!kinds.contains(&CheckKind::Recipe), "an alteration must not show as a recipe difference:\n{report}");
    kinds
}

#[test]
fn an_unadjusted_loss_gamma_fails() {
    let Some(report) = run("an_unadjusted_loss_gamma_fails", Alteration::UnadjustedGamma) else { return };
    let kinds = failing_kinds(&report);
    assert!(kinds.contains(&CheckKind::Loss), "the loss must be off: {kinds:?}\n{report}");
    assert!(report.summary().ends_with(": FAILED"), "{}", report.summary());
}

#[test]
fn training_without_the_clip_fails() {
    let Some(report) = run("training_without_the_clip_fails", Alteration::NoClip) else { return };
    let kinds = failing_kinds(&report);
    assert!(kinds.contains(&CheckKind::Update), "the updates must be off: {kinds:?}\n{report}");
    assert!(report.summary().ends_with(": FAILED"), "{}", report.summary());
}

#[test]
fn adamw_without_bias_correction_fails() {
    let Some(report) = run("adamw_without_bias_correction_fails", Alteration::NoBiasCorrection) else { return };
    let kinds = failing_kinds(&report);
    assert!(kinds.contains(&CheckKind::Update), "the updates must be off: {kinds:?}\n{report}");
    assert!(report.summary().ends_with(": FAILED"), "{}", report.summary());
}

#[test]
fn a_schedule_without_warm_up_fails() {
    let Some(report) = run("a_schedule_without_warm_up_fails", Alteration::NoWarmup) else { return };
    let kinds = failing_kinds(&report);
    assert!(kinds.contains(&CheckKind::LearningRate), "the learning rate must be off: {kinds:?}\n{report}");
    assert!(report.summary().ends_with(": FAILED"), "{}", report.summary());
}
