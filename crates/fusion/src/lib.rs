//! Fusion of an image with its depth prior.
//!
//! The [`ImageFusion`] stage maps an image and its relative depth to the "enhanced image" that the
//! encoders see, in the same 0..255 range as the input. Three kinds, chosen by [`FusionConfig`]:
//!
//! - `none`: the image passes unchanged (plain RAFT-Stereo);
//! - `deformable`: DGIA, the paper's depth-guided image augmentation ([`DeformableFusion`]): 1x1
//!   convs lift the image and the depth prior to `F = 8` channels each, a 3x3 conv on the depth
//!   features predicts the offsets of a 3x3 deformable conv that maps both feature sets back to
//!   RGB;
//! - `conv`: the paper's "Depth+CNN" ablation ([`ConvFusion`]): the same with a plain 3x3 conv.
//!
//! # Design
//! - The depth prior enters normalised per image to `[0, 1]` (min-max, guarded for constant
//!   maps) and scaled by 255 like the images ([`normalize_depth`]); a prior at another resolution
//!   is resized bilinearly to the image's.
//! - One module serves both views (shared weights); images of a batch never interact, so the
//!   model may fuse the views one at a time or stacked in one batch.
//! - Both learned kinds start close to the identity on the image so the pretrained encoders see
//!   what they expect at step 0; [`init`] documents how.
//! - Where the enhanced image goes (both encoders, or the context encoder only while the feature
//!   encoder keeps the raw image) is the model's decision; the config carries it as
//!   [`FusionTarget`], read through [`FusionConfig::target`].
//! - The stage's contract is the trait [`ImageFusion`]: each kind's module implements it,
//!   [`Fusion`], the module a configuration built, delegates to its variant with one `match`,
//!   and `tests/stage_contract.rs` runs every fusion through one body generic over the trait.
//!
//! # Config (TOML)
//! ```toml
//! [fusion]
//! kind = "deformable"        # or "none" (default), "conv"
//! target = "both"            # or "context-only"; default "both"
//! features = 8               # channels of F_i and F_d; default 8
//! ```
//! Every kind refuses a key it does not have (`none` has none).
//!
//! # Training
//! Build on the autodiff device, or build on a plain device and call
//! `fusion.fork(&autodiff_device).train()`: in burn 0.22 a forked module tracks gradients only
//! after `train()`.
#![deny(missing_docs)]

pub mod conv;
pub mod deformable;
pub mod depth;
pub mod init;
pub mod projection;

pub use conv::ConvFusion;
pub use deformable::DeformableFusion;
pub use depth::normalize_depth;
pub use projection::FeatureProjection;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dgstereo_core::{Error, Problem, Result};
use serde::{Deserialize, Serialize};

/// The stage trait.
///
/// # Shapes
/// - `image`: `[N, 3, H, W]`, 0..255
/// - `depth`: `[N, 1, H, W]`, relative depth (any scale; the fusion normalises it per image)
/// - output: `[N, 3, H, W]`, 0..255
pub trait ImageFusion {
    /// The enhanced image.
    ///
    /// # Errors
    /// [`Error::Config`] naming `fusion.kind` when a fusion that needs the depth prior
    /// ([`FusionConfig::needs_prior`]) gets `depth = None`.
    fn fuse(&self, image: Tensor<4>, depth: Option<Tensor<4>>) -> Result<Tensor<4>>;
}

/// The error of a learned fusion of kind `kind` run without its depth prior.
pub(crate) fn missing_prior(kind: &str) -> Error {
    Error::config("fusion.kind", format!("{kind} fusion needs the depth prior, but none was given"))
}

/// Which encoders see the enhanced image. Applied by the model, not by the fusion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FusionTarget {
    /// Feature and context encoders both see the enhanced image.
    #[default]
    Both,
    /// Only the context encoder sees it; the feature (matching) encoder keeps the raw image.
    ContextOnly,
}

/// The paper's feature channel count per branch.
pub const DEFAULT_FEATURES: usize = 8;

fn default_features() -> usize {
    DEFAULT_FEATURES
}

/// Which fusion an experiment uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum FusionConfig {
    /// The image passes unchanged.
    None {},
    /// DGIA: depth-guided deformable conv ([`DeformableFusion`]).
    Deformable {
        /// Which encoders see the enhanced image.
        #[serde(default)]
        target: FusionTarget,
        /// Channels of each of `F_i` and `F_d` (at least 3).
        #[serde(default = "default_features")]
        features: usize,
    },
    /// Depth+CNN: plain 3x3 conv over the image and depth features ([`ConvFusion`]).
    Conv {
        /// Which encoders see the enhanced image.
        #[serde(default)]
        target: FusionTarget,
        /// Channels of each of `F_i` and `F_d` (at least 3).
        #[serde(default = "default_features")]
        features: usize,
    },
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self::None {}
    }
}

impl FusionConfig {
    /// One configuration of every kind, with the paper's parameters, in the order of the enum.
    /// Tests and the experiment crate's checks draw the kinds from here, so a new kind is
    /// listed once, in this crate (`every_kind_is_listed` in the tests fails otherwise).
    pub fn variants() -> Vec<Self> {
        vec![Self::None {}, Self::deformable(), Self::conv()]
    }

    /// The kind's name as the TOML key `kind` writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::None {} => "none",
            Self::Deformable { .. } => "deformable",
            Self::Conv { .. } => "conv",
        }
    }

    /// This kind with `target` and `features` where the kind has them (`none` has neither).
    #[must_use]
    pub fn with_parameters(&self, target: FusionTarget, features: usize) -> Self {
        match self {
            Self::None {} => Self::None {},
            Self::Deformable { .. } => Self::Deformable { target, features },
            Self::Conv { .. } => Self::Conv { target, features },
        }
    }

    /// The DGIA config with the paper's defaults (`target = "both"`, `features = 8`).
    pub fn deformable() -> Self {
        Self::Deformable { target: FusionTarget::default(), features: DEFAULT_FEATURES }
    }

    /// The Depth+CNN config with the paper's defaults.
    pub fn conv() -> Self {
        Self::Conv { target: FusionTarget::default(), features: DEFAULT_FEATURES }
    }

    /// Which encoders see the enhanced image; [`FusionTarget::Both`] for `none` (where the
    /// enhanced image is the image itself).
    pub fn target(&self) -> FusionTarget {
        match self {
            Self::None {} => FusionTarget::Both,
            Self::Deformable { target, .. } | Self::Conv { target, .. } => *target,
        }
    }

    /// Whether [`ImageFusion::fuse`] needs the depth prior (`Some(depth)`); the model can skip
    /// running the prior network when it does not.
    pub fn needs_prior(&self) -> bool {
        !matches!(self, Self::None {})
    }

    /// Everything wrong with the parameters, keys relative to the fusion table (`features`).
    pub fn problems(&self) -> Vec<Problem> {
        match self {
            Self::None {} => Vec::new(),
            Self::Deformable { features, .. } | Self::Conv { features, .. } => {
                projection::features_problem(*features).into_iter().collect()
            }
        }
    }

    /// Checks the parameters.
    ///
    /// # Errors
    /// [`Error::Config`] with the first of [`problems`](Self::problems) (`features < 3`).
    pub fn validate(&self) -> Result<()> {
        Problem::first(self.problems())
    }

    /// Builds the module.
    ///
    /// # Errors
    /// [`Error::Config`] when [`validate`](Self::validate) fails.
    pub fn init(&self, device: &Device) -> Result<Fusion> {
        Ok(match self {
            Self::None {} => Fusion::None(IdentityFusion),
            Self::Deformable { features, .. } => Fusion::Deformable(DeformableFusion::new(*features, device)?),
            Self::Conv { features, .. } => Fusion::Conv(ConvFusion::new(*features, device)?),
        })
    }
}

/// The `none` fusion: returns the image unchanged. (burn's `Module` derive does not accept unit
/// enum variants, hence this stateless module in [`Fusion::None`].)
#[derive(Module, Debug, Default)]
pub struct IdentityFusion;

impl ImageFusion for IdentityFusion {
    fn fuse(&self, image: Tensor<4>, _depth: Option<Tensor<4>>) -> Result<Tensor<4>> {
        Ok(image)
    }
}

/// A built fusion module, chosen by [`FusionConfig`].
// One per model: the size gap between the identity and the learned variants does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Fusion {
    /// The image passes unchanged.
    None(IdentityFusion),
    /// DGIA.
    Deformable(DeformableFusion),
    /// Depth+CNN.
    Conv(ConvFusion),
}

impl ImageFusion for Fusion {
    fn fuse(&self, image: Tensor<4>, depth: Option<Tensor<4>>) -> Result<Tensor<4>> {
        match self {
            Self::None(fusion) => fusion.fuse(image, depth),
            Self::Deformable(fusion) => fusion.fuse(image, depth),
            Self::Conv(fusion) => fusion.fuse(image, depth),
        }
    }
}
