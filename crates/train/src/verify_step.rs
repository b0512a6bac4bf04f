//! Conformance of the trainer with the official training loop: two steps against a reference.
//!
//! The reference (`../shared/golden/raft_stereo_random.train_step.safetensors`, see its README)
//! is two steps of `train_stereo.py` on a fixed batch from an official checkpoint: every
//! iteration's prediction, the losses, the gradient norms before clipping, the learning rates,
//! 30 gradients and the parameters after step 2. [`verify_train_step`] runs the trainer's own
//! step ([`crate::Trainer::step_on`]: the configured loss, global-norm clipping, AdamW and the
//! one-cycle schedule, frozen batch norm) with an experiment's recipe on that batch and compares
//! each with the tolerances of [`report`].
//!
//! Design decision: parameters are compared through their updates `p2 - p0`, not their values,
//! since Adam turns a tiny noisy gradient into a full-size step of either sign; and the recipe's
//! values are checked against the reference's first, so a difference of recipe shows as a
//! configuration key, not as a mismatch of numbers. [`Alteration`] breaks one component on
//! purpose, to show that the checks catch it.

pub mod alteration;
pub mod reference;
pub mod report;
mod run;

pub use alteration::Alteration;
pub use reference::TrainStepReference;
pub use report::{CheckKind, CheckLine, TrainStepReport};
pub use run::verify_train_step;
