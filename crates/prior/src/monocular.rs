//! The monocular depth network inside a stereo network (`[model.monocular]`).
//!
//! Unlike a [`crate::PriorProvider`], which hands the model a finished depth map per view from
//! outside, this network is part of the stereo network: its weights live in the stereo
//! checkpoint, and its features feed the encoders (DEFOM-Stereo's `defomencoder`). `none` is
//! RAFT-Stereo's (and the paper's) choice.

use burn::tensor::Device;
use dgstereo_core::Problem;
use serde::{Deserialize, Serialize};

use crate::depth_anything::{DepthAnythingV2Encoder, DepthAnythingV2Features};

/// Which monocular network the stereo network embeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MonocularConfig {
    /// None (RAFT-Stereo).
    None {},
    /// Depth Anything V2 with DEFOM-Stereo's feature trunk ([`DepthAnythingV2Features`]).
    DepthAnythingV2 {
        /// The ViT size (`vits`, `vitb`, `vitl`).
        #[serde(default)]
        encoder: DepthAnythingV2Encoder,
    },
}

impl Default for MonocularConfig {
    fn default() -> Self {
        Self::None {}
    }
}

impl MonocularConfig {
    /// One configuration of every kind, in the order of the enum (the kinds tests, property
    /// strategies and experiment checks draw from).
    pub fn variants() -> Vec<Self> {
        vec![Self::None {}, Self::DepthAnythingV2 { encoder: DepthAnythingV2Encoder::Vits }]
    }

    /// The kind's name as the TOML key `kind` writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::None {} => "none",
            Self::DepthAnythingV2 { .. } => "depth-anything-v2",
        }
    }

    /// The width of the features it hands the encoders, `None` without a network.
    pub fn feature_channels(&self) -> Option<usize> {
        match self {
            Self::None {} => None,
            Self::DepthAnythingV2 { encoder } => Some(encoder.features()),
        }
    }

    /// Everything wrong with the options, keys relative to its table (none: every encoder size
    /// builds).
    pub fn problems(&self) -> Vec<Problem> {
        Vec::new()
    }

    /// Builds the network, fresh weights (a checkpoint replaces them); `None` for `none`.
    pub fn init(&self, device: &Device) -> Option<DepthAnythingV2Features> {
        match self {
            Self::None {} => None,
            Self::DepthAnythingV2 { encoder } => Some(DepthAnythingV2Features::new(*encoder, device)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kind serde accepts is listed, and each listed kind reads back from its TOML.
    #[test]
    fn every_kind_is_listed() {
        let listed: Vec<&str> = MonocularConfig::variants().iter().map(|v| v.kind()).collect();
        assert_eq!(listed, dgstereo_core::serde_names::accepted_kinds::<MonocularConfig>("kind").unwrap());
        for variant in MonocularConfig::variants() {
            let text = format!("kind = \"{}\"", variant.kind());
            let back: MonocularConfig = toml::from_str(&text).unwrap();
            assert_eq!(back, variant);
        }
        let vitl: MonocularConfig = toml::from_str("kind = \"depth-anything-v2\"\nencoder = \"vitl\"").unwrap();
        assert_eq!(vitl.feature_channels(), Some(256));
        assert!(toml::from_str::<MonocularConfig>("kind = \"midas\"").is_err());
        assert!(toml::from_str::<MonocularConfig>("kind = \"none\"\nencoder = \"vitl\"").is_err());
        assert!(toml::from_str::<MonocularConfig>("kind = \"depth-anything-v2\"\nwidth = 3").is_err());
    }
}
