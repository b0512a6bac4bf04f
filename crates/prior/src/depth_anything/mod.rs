//! Depth Anything V2 on burn: the network, its preprocessing, checkpoint loading and a
//! conformance check against reference activations.
//!
//! The model is the official one layer for layer ([`dinov2`] encoder + [`dpt`] head), so the
//! official `depth_anything_v2_vit{s,b,l}.pth` files load without conversion
//! ([`checkpoint`]). [`DepthAnythingV2::infer`] is the official `infer_image` on a batch of
//! tensors: resize to a multiple of 14 with the short side at least `input_size`, ImageNet
//! normalisation, network, bilinear resize back ([`preprocess`]). [`features`] is the network as
//! DEFOM-Stereo embeds it in a stereo network, with its feature trunk beside the depth head.

pub mod checkpoint;
pub mod cubic;
pub mod dinov2;
pub mod dpt;
mod encoder;
pub mod features;
mod model;
pub mod preprocess;
mod provider;
pub mod verify;

pub use encoder::DepthAnythingV2Encoder;
pub use features::DepthAnythingV2Features;
pub use model::{DepthAnythingV2, DepthAnythingV2Output};
pub use provider::DepthAnythingV2Prior;
