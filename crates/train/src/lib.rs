//! Training (optimiser, schedule, clipping, checkpoints, loop) of dgstereo models.
#![deny(missing_docs)]

mod config;

pub use config::{TrainingConfig, TrainingDataConfig};
