//! The encoder sizes of Depth Anything V2 (ViT-S, ViT-B, ViT-L) and their official configurations.

use serde::{Deserialize, Serialize};

use super::dinov2::VitSpec;

/// The encoder size of a Depth Anything V2 model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum DepthAnythingV2Encoder {
    /// ViT-S/14: 24.8 M parameters.
    #[default]
    Vits,
    /// ViT-B/14: 97.5 M parameters.
    Vitb,
    /// ViT-L/14: 335.3 M parameters.
    Vitl,
}

impl DepthAnythingV2Encoder {
    /// All sizes, smallest first.
    pub const ALL: [Self; 3] = [Self::Vits, Self::Vitb, Self::Vitl];

    /// The name used upstream (`vits`, `vitb`, `vitl`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Vits => "vits",
            Self::Vitb => "vitb",
            Self::Vitl => "vitl",
        }
    }

    /// Width, depth and heads of the ViT.
    pub fn vit(self) -> VitSpec {
        match self {
            Self::Vits => VitSpec { embed_dim: 384, depth: 12, heads: 6 },
            Self::Vitb => VitSpec { embed_dim: 768, depth: 12, heads: 12 },
            Self::Vitl => VitSpec { embed_dim: 1024, depth: 24, heads: 16 },
        }
    }

    /// Channels of the DPT head's fusion path (`features`).
    pub fn features(self) -> usize {
        match self {
            Self::Vits => 64,
            Self::Vitb => 128,
            Self::Vitl => 256,
        }
    }

    /// Channels of the four reassembled levels (`out_channels`).
    pub fn out_channels(self) -> [usize; 4] {
        match self {
            Self::Vits => [48, 96, 192, 384],
            Self::Vitb => [96, 192, 384, 768],
            Self::Vitl => [256, 512, 1024, 1024],
        }
    }

    /// The 0-based blocks the head reads (`intermediate_layer_idx`).
    pub fn intermediate_layers(self) -> [usize; 4] {
        match self {
            Self::Vits | Self::Vitb => [2, 5, 8, 11],
            Self::Vitl => [4, 11, 17, 23],
        }
    }

    /// The size whose token width is `embed_dim`, if any.
    pub fn from_embed_dim(embed_dim: usize) -> Option<Self> {
        Self::ALL.into_iter().find(|e| e.vit().embed_dim == embed_dim)
    }
}

impl std::fmt::Display for DepthAnythingV2Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
