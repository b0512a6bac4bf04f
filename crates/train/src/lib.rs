//! Training of dgstereo models: RAFT-Stereo's recipe, reproducible, resumable and observable.
//!
//! The pieces burn lacks are here: PyTorch's one-cycle schedule ([`schedule`]) and global-norm
//! gradient clipping ([`clip`]); AdamW is burn-optim's. [`Trainer::step`] takes one step: a batch
//! that is a pure function of `(seed, step)` ([`batch`]), the configured prior, the network over
//! all training iterations on the autodiff device, the configured loss, backward, clipping,
//! AdamW at the schedule's rate. BatchNorm is frozen by construction (the encoder's
//! `FrozenBatchNorm` always normalises with running statistics that have no gradient).
//!
//! Design decision: resumability comes from determinism, not from saving random generators.
//! Since the data of step `k` depends only on the seed and `k`, and the schedule only on `k`, a
//! checkpoint ([`checkpoint`]) holding the weights, the optimiser state, the parameter identities
//! and the step reproduces an uninterrupted run exactly. [`run::train`] is the loop: logging
//! (JSONL), [`progress`] events for the binary to draw, validation, plots and atomic checkpoints
//! that keep the last N.
//! DEFOM-Stereo's recipe adds two keys: `train.monocular_init` loads Depth Anything V2 weights
//! into the monocular network ([`monocular_init`]) and `train.frozen` keeps parameters out of
//! training ([`frozen`]). IGEV-Stereo's adds `train.feature_init`, timm's ImageNet MobileNetV2 in
//! the feature trunk ([`feature_init`]); [`start_weights`] loads what a fresh run starts from. Its
//! loss reads the network's upsampled initial disparity beside the iterations' (the loss
//! crate's `Predictions`, the model's `TrainingDisparities`).
//! `train.ema_decay` adds a moving average of the weights ([`ema`]) that validation, checkpoints'
//! model weights and the final model use. [`verify_step`] checks two steps against the official
//! training loop. A study of many runs (scores, tables, the paper's layout) is the
//! `dgstereo-study` crate's, above this one.
//!
//! The configuration it executes (`[train]`, `[data]`) is the experiment crate's schema
//! ([`dgstereo_experiment::TrainingConfig`], [`dgstereo_experiment::TrainingDataConfig`]): the
//! trainer depends on the schema, never the reverse, so reading an experiment (inference, the
//! Python package) does not pull in the trainer.
//!
//! Data parallelism is one seam: a run is `N` ranks meeting through a
//! [`dgstereo_collective::Collective`] (the world of one is
//! [`dgstereo_collective::SingleProcess`]; MPI's lives in `dgstereo-distributed`).
//! [`Trainer::step_among`] splits the global batch among them and sums their gradients
//! ([`data_parallel`], [`gradient_exchange`]); [`train_among`] is the loop in which rank 0 alone
//! writes the run's files.
#![deny(missing_docs)]

pub mod batch;
pub mod checkpoint;
pub mod clip;
pub mod data_parallel;
pub mod ema;
pub mod feature_init;
pub mod frozen;
pub mod gradient_exchange;
pub mod monocular_init;
pub mod params;
pub mod plot;
pub mod preflight;
pub mod progress;
pub mod run;
pub mod run_identity;
pub mod run_log;
pub mod schedule;
pub mod start_weights;
pub mod step_timing;
pub mod timed_steps;
pub mod trainer;
pub mod validate;
pub mod verify_step;

pub use progress::{Progress, ProgressObserver};
pub use run::{RunOptions, RunSummary, train, train_among};
pub use schedule::OneCycleLr;
pub use trainer::{StepInternals, StepReport, TrainParts, Trainer};
