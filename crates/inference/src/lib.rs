//! Running a trained model on stereo pairs: what the command line's `infer`, `eval`, `demo` and
//! `bench` share, and what the Python package binds.
//!
//! ```text
//! let engine = Engine::load(&EngineConfig { weights: Some(path), ..Default::default() })?;
//! let prediction = engine.predict(&left, &right, "pair", &PredictOptions::default())?;
//! // prediction.disparity: a DisparityMap at the left image's size; prediction.info: RunInfo
//! ```
//!
//! Design decision: an [`Engine`] is loaded once from an [`EngineConfig`] (weights, model and
//! prior configurations, device) and holds no per-pair policy; each [`Engine::predict`] call
//! takes its [`PredictOptions`] (iterations, working size, cost volume, left-right check), so one
//! loaded model serves callers with different needs. Inputs and outputs are the data crate's
//! plain arrays ([`RgbImage`]: channel-major `f32` in 0-255; [`DisparityMap`]: row-major `f32`),
//! which a binding fills from and turns into NumPy arrays without knowing burn. The engine is
//! `Send + Sync` (a test checks it) and `predict` takes `&self`, so a binding may release the
//! interpreter's lock around it. The library never prints: what loading chose on the caller's
//! behalf comes back as [`Engine::notes`], and its errors are [`dgstereo_core::Error`]s naming
//! files ([`dgstereo_core::Error::Io`], [`dgstereo_core::Error::Format`]) or option fields (an
//! invalid option is [`dgstereo_core::Error::config`]`("min_size", reason)`), never command-line
//! flags; each front end spells the field its own way (`--min-size`, a keyword argument).
//!
//! Beside the engine: [`working_size`] (the min/max size policy), [`cost_volume`] (materialised
//! or on-the-fly volume within a memory budget), [`consistency`] (the left-right check),
//! [`calibration`] (one [`Calibration`] from Middlebury, JSON or `K.txt` files), [`pointcloud`]
//! (depth, coloured point clouds, PLY), [`outputs`] (the files written for a pair, one
//! [`outputs::SaveKind`] a file), [`pair_files`] (one pair from its files to its outputs, its
//! failure its own), [`timing`] (whole inference timed as a user waits for it), [`specs`] (what
//! front ends read from their users' words alike) and [`weights`] (bundled assets, default
//! weights, loading a checkpoint).

#![deny(missing_docs)]

pub mod calibration;
pub mod consistency;
pub mod convert;
pub mod cost_volume;
mod engine;
pub mod options;
pub mod outputs;
pub mod pair_files;
pub mod pointcloud;
mod prior_maps;
pub mod specs;
pub mod timing;
pub mod weights;
pub mod working_size;

pub use calibration::Calibration;
pub use cost_volume::{CorrChoice, DEFAULT_MEMORY_BUDGET, corr_for};
pub use dgstereo_data::{DisparityMap, Mask, RgbImage};
pub use engine::{Engine, Prediction, PriorMaps, RunInfo, check_same_size};
pub use options::{EngineConfig, PredictOptions};
pub use pointcloud::{PlyEncoding, PointCloud};
pub use specs::{
    ModelChoice, error_chain, experiment_configs, model_config_file, parse_byte_size, parse_prior, prior_with_weights,
};
pub use working_size::MinSize;
