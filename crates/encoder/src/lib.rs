//! RAFT-Stereo's encoders: matching features and multi-level context.
//!
//! Both encoders share the reference's residual trunk; the feature encoder ends in a 1x1
//! projection at 1/4 resolution, the context encoder in two heads per level at 1/4, 1/8 and
//! 1/16. Field names mirror the reference's state dict so official checkpoints load by path.
//! The normalisations ([`norm`]) are swappable by [`NormKind`].
//!
//! The layout (separate feature and context encoders, one shared backbone, or IGEV-Stereo's
//! MobileNetV2 pyramid beside the context encoder) is one [`EncoderLayout`] variant, so options
//! that belong to one layout cannot meet another's: [`EncoderConfig::init`] builds an
//! [`Encoders`] module with one `match`, and the model calls it through the stage trait, so a new
//! layout touches this crate and the experiment files only.
//!
//! Design decision: the stage's contract is the trait [`StereoEncoder`] (both views' features,
//! the context, the input normalisation). Every layout implements it, [`Encoders`] delegates to
//! its variant with one `match`, and `tests/layouts.rs` runs every layout through one body
//! generic over the trait. The feature and context encoders inside a layout are plain modules
//! with one implementation each, so they have no trait of their own.
//!
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
pub mod pyramid;
pub mod residual;

use burn::tensor::Tensor;
use dgstereo_core::{Probe, Result};

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

/// The stage trait: what every encoder layout gives the rest of the network. Each layout
/// ([`SeparateEncoders`], [`SharedBackbone`], [`PyramidEncoders`]) implements it; [`Encoders`],
/// the layout a configuration built, implements it by delegating with one `match`, and the model
/// calls it there.
///
/// # Shapes
/// - inputs: `[N, 3, H, W]` in 0..255; `fmap1`, `fmap2`: `[N, C, H/f, W/f]` with `f =
///   2^n_downsample`; context: `levels` levels, finest first ([`ContextFeatures`])
pub trait StereoEncoder {
    /// How images in 0..255 become the encoders' input (the monocular network of DEFOM-Stereo
    /// reads them so normalised too).
    fn normalisation(&self) -> InputNormalisation;

    /// Whether the encoders add a monocular network's features (and so need them).
    fn takes_depth_features(&self) -> bool;

    /// Features of both views and the context of `levels` GRU levels, timed on `probe` as the
    /// `feature encoder` and `context encoder` stages.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] keyed `encoder.depth_features` when the encoders add
    /// monocular features and `inputs.depth` is `None`, or do not and it is given.
    fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Result<Encoded>;
}
