//! Shared types of the dgstereo workspace.
//!
//! Every stage crate (prior, fusion, encoder, cost volume, updater, loss) depends on this crate
//! and on nothing else of the workspace, so the stages stay swappable and independent. What lives
//! here is what more than one stage needs: the device choice, the error type, the input padder
//! that makes any image size a multiple of 32, fixed bilinear resampling expressed as matrix
//! products (they differentiate on every backend, unlike the GPU backends' resize), a few tensor
//! helpers, the locator of the shared reference data, the stage clock of the profiler and the allocator
//! setting the binaries make at start.
#![deny(missing_docs)]

pub mod allocator;
pub mod device;
pub mod error;
pub mod gpu_routes;
pub mod host_conv;
mod host_few_outputs;
pub mod host_norm;
mod host_winograd;
pub mod layers;
pub mod matmul_conv;
pub mod padding;
pub mod resample;
pub mod shared;
pub mod tensor;
pub mod timing;

pub use device::{DeviceChoice, default_device};
pub use error::{Error, Result};
pub use padding::InputPadder;

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
