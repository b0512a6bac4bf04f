//! The training run's configuration: [`TrainingConfig`] (the `[train]` table) and
//! [`TrainingDataConfig`] (the `[data]` table) with its sources and validation set.
//!
//! Every key has a default (RAFT-Stereo's recipe as used by the paper), so an empty table is the
//! reference run; unknown keys are errors naming the key. Each configuration lists what is wrong
//! with it as [`Problem`](dgstereo_core::Problem)s keyed relative to its own table (`steps`,
//! `sources[0].weight`), which the experiment crate gathers under the table; `validate`, used
//! where a table is checked on its own, names the key as an experiment file writes it
//! (`train.steps`, `data.sources[0].weight`). The keys of a synthetic scene
//! mix are written once ([`SyntheticScenes`]) and flattened into both a synthetic source and the
//! validation set, so both read the same TOML keys.

mod data;
mod recipe;
mod scenes;
mod source;
mod validation_set;

pub use data::TrainingDataConfig;
pub use recipe::TrainingConfig;
pub use scenes::{PhotoTextures, SyntheticScenes};
pub use source::DataSource;
pub use validation_set::ValidationConfig;
