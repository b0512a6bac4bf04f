//! Monocular depth priors.
//!
//! A [`PriorProvider`] turns a stereo pair into a relative depth map per view (larger = nearer,
//! as Depth Anything V2's output). The model never knows where the prior came from, so the
//! provider is a configuration choice ([`PriorConfig`], the `[prior]` table of an experiment):
//!
//! - `depth-anything-v2`: the network itself, on burn ([`depth_anything`]), loading the official
//!   checkpoints unchanged and checked against the official code's activations
//!   ([`depth_anything::verify`]);
//! - `file`: priors computed elsewhere, read from `.npy`, `.pfm` or 16-bit `.png` files
//!   ([`mod@file`], [`formats`]);
//! - `cache`: any provider, with its outputs stored on disk by a hash of the image content and
//!   the provider's configuration ([`cache`]);
//! - `simulated`: a prior made from ground-truth disparity with documented, controlled errors,
//!   for training and ablations without running a network ([`simulated`]);
//! - `none`: no prior, which makes the model plain RAFT-Stereo.
//!
//! A stereo network may also embed a monocular network whose weights are its own
//! ([`MonocularConfig`], `[model.monocular]`: DEFOM-Stereo's Depth Anything V2 with a feature
//! trunk, [`DepthAnythingV2Features`]); the model crate composes it like the other stages.
//!
//! Design decision: every provider returns plain tensors in one convention (relative inverse
//! depth, arbitrary scale and shift, non-negative, at the image resolution) and the fusion stage
//! normalises them. A provider never falls back silently: a missing checkpoint, file or
//! ground truth is an error naming the configuration key or the file. The stage's contract is the
//! trait [`PriorProvider`]: each provider implements it, [`Prior`], the provider a configuration
//! built, delegates to its variant with one `match`, [`CachedPrior`] wraps any implementation,
//! and `tests/stage_contract.rs` runs the providers through one body generic over the trait.
#![deny(missing_docs)]

pub mod cache;
mod config;
pub mod content_hash;
pub mod depth_anything;
pub mod file;
pub mod formats;
pub mod monocular;
pub mod safetensors_io;
pub mod simulated;

use burn::tensor::Tensor;
use dgstereo_core::Result;

pub use cache::CachedPrior;
pub use config::{Prior, PriorConfig};
pub use depth_anything::preprocess::DEFAULT_INPUT_SIZE;
pub use depth_anything::verify::{TensorComparison, VerificationReport, verify_depth_anything_v2};
pub use depth_anything::{DepthAnythingV2, DepthAnythingV2Encoder, DepthAnythingV2Features, DepthAnythingV2Prior};
pub use file::FilePrior;
pub use monocular::MonocularConfig;
pub use simulated::{SimulatedPrior, SimulatedPriorConfig};

/// The inputs a provider may use.
///
/// # Shapes
/// - `left`, `right`: `[N, 3, H, W]`, RGB in 0..255
/// - `gt_disparity`: `[N, 1, H, W]`, positive disparity of the left view (training only)
#[derive(Debug, Clone)]
pub struct PriorInput {
    /// Left images.
    pub left: Tensor<4>,
    /// Right images.
    pub right: Tensor<4>,
    /// Ground-truth left disparity, when known (training, simulated priors).
    pub gt_disparity: Option<Tensor<4>>,
    /// Names of the pairs (for file-based providers), one per batch element.
    pub names: Vec<String>,
}

pub use dgstereo_core::DepthPrior;

/// The stage trait: a stereo pair in, a relative depth per view (or none) out.
pub trait PriorProvider {
    /// Computes the prior of a batch of pairs; `Ok(None)` when this provider gives none.
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>>;
}

impl<P: PriorProvider + ?Sized> PriorProvider for Box<P> {
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>> {
        (**self).provide(input)
    }
}
