//! Shared types of the dgstereo workspace.
//!
//! Every stage crate (prior, fusion, encoder, cost volume, updater, loss) depends on this crate
//! and on the kernels and formats crates only, never on another stage, so the stages stay
//! swappable and independent. What lives
//! here is what more than one stage needs: the device and precision choice, the error type, the
//! input padder that makes any image size a multiple of 32, a few tensor helpers, the locator of
//! the shared reference data, the atomic replacement of output files, the stage clock of the profiler and the probe through which a
//! forward pass reports its intermediate tensors and stage times, and the notation of
//! checkpoint-key renames that the prior and model crates write their tables in. The kernels live in
//! `dgstereo-kernels`, which depends on this crate.
#![deny(missing_docs)]

pub mod atomic_file;
pub mod batch_norm;
pub mod conv_blocks;
pub mod device;
pub mod error;
pub mod key_notation;
pub mod layers;
pub mod padding;
pub mod probe;
pub mod random_values;
pub mod serde_names;
pub mod shared;
pub mod tensor;
pub mod timing;

pub use device::{DeviceChoice, default_device};
pub use error::{Error, Problem, Result};
pub use padding::InputPadder;
pub use probe::{Probe, Trace};

/// A relative depth map per view, as the prior stage produces it.
///
/// # Shapes
/// - `left`, `right`: `[N, 1, H, W]`, relative inverse depth (larger = nearer), any scale
#[derive(Debug, Clone)]
pub struct DepthPrior {
    /// Prior of the left view.
    pub left: burn::tensor::Tensor<4>,
    /// Prior of the right view.
    pub right: burn::tensor::Tensor<4>,
}

/// What a monocular depth network inside the stereo network hands on (DEFOM-Stereo's embedded
/// Depth Anything V2): features for the encoders and the left view's inverse depth, for the
/// disparity initialiser. `f` is the update grid's stride `2^n_downsample`.
///
/// # Shapes
/// - `context[l]`: `[N, F, H/(f·2^l), W/(f·2^l)]`, `l = 0, 1, 2` (left view)
/// - `left`, `right`: `[N, F, H/f, W/f]`
/// - `inverse_depth`: `[N, 1, H/f, W/f]`, relative (larger = nearer), non-negative
#[derive(Debug, Clone)]
pub struct MonocularFeatures {
    /// The left view's features at the context encoder's three levels, finest first.
    pub context: Vec<burn::tensor::Tensor<4>>,
    /// The left view's features at the update grid, for the feature encoder.
    pub left: burn::tensor::Tensor<4>,
    /// The right view's features at the update grid, for the feature encoder.
    pub right: burn::tensor::Tensor<4>,
    /// The left view's relative inverse depth at the update grid.
    pub inverse_depth: burn::tensor::Tensor<4>,
}
