//! RAFT-Stereo's encoders: matching features and multi-level context.
//!
//! Both encoders share the reference's residual trunk; the feature encoder ends in a 1x1
//! projection at 1/4 resolution, the context encoder in two heads per level at 1/4, 1/8 and
//! 1/16. Field names mirror the reference's state dict so official checkpoints load by path.
//! The stage traits [`FeatureExtractor`] and [`ContextExtractor`] are what single-stage tools
//! call; the normalisations ([`norm`]) are swappable by [`NormKind`].
//!
//! The layout (separate feature and context encoders, one shared backbone, or IGEV-Stereo's
//! MobileNetV2 pyramid beside the context encoder) is one [`EncoderLayout`] variant, so options
//! that belong to one layout cannot meet another's: [`EncoderConfig::init`] builds an
//! [`Encoders`] module with one `match`, and the model
//! calls [`Encoders::encode`], so a new layout touches this crate and the experiment files only.
//! The layout is a module enum, so its variant name is part of each module path
//! (`encoder.Separate.fnet...`); checkpoints keep the reference's keys (`fnet.`, `cnet.`,
//! `conv2.`), and the model's checkpoint code maps between the two.
//!
//! DEFOM-Stereo's combined encoders are a variant of the separate layout
//! ([`DepthFeatureInput::Added`]): a monocular network's features are added after the trunks
//! ([`depth_block`]) and the images are ImageNet-normalised.
#![deny(missing_docs)]

pub mod config;
pub mod context;
pub mod depth_block;
pub mod feature;
pub mod layout;
pub mod mobilenet;
pub mod norm;
pub mod official_keys;
pub mod pyramid;
pub mod residual;

use burn::tensor::Tensor;

pub use config::{EncoderConfig, EncoderLayout};
pub use context::ContextEncoder;
pub use depth_block::{DepthFeatureBlock, DepthFeatureInput, InputNormalisation};
pub use feature::{FeatureEncoder, SharedFeatureHead};
pub use layout::{Encoded, EncoderInputs, Encoders, PyramidEncoders, SeparateEncoders, SharedBackbone};
pub use norm::NormKind;
pub use pyramid::{FeaturePyramid, MobileNetPyramid};

/// Context of each GRU level, finest first: `[hidden, context]` before their activations.
#[derive(Debug, Clone)]
pub struct ContextFeatures {
    /// One `[hidden_head, context_head]` pair per level (1/4, 1/8, 1/16).
    pub levels: Vec<[Tensor<4>; 2]>,
}

/// The feature-encoder stage.
///
/// # Shapes
/// - `images`: `[N, 3, H, W]`, normalised to -1..1; output `[N, C, H/f, W/f]`
pub trait FeatureExtractor {
    /// Matching features of a batch of images.
    fn features(&self, images: Tensor<4>) -> Tensor<4>;
}

/// The context-encoder stage.
pub trait ContextExtractor {
    /// Context for `levels` GRU levels of a batch of (left) images.
    fn context(&self, image: Tensor<4>, levels: usize) -> ContextFeatures;
}
