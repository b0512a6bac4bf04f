//! Depth Anything V2 on burn: the network, its preprocessing, checkpoint loading and a
//! conformance check against reference activations.
//!
//! The model is the official one layer for layer ([`dinov2`] encoder + [`dpt`] head), so the
//! official `depth_anything_v2_vit{s,b,l}.pth` files load without conversion
//! ([`checkpoint`]). [`DepthAnythingV2::infer`] is the official `infer_image` on a batch of
//! tensors: resize to a multiple of 14 with the short side at least `input_size`, ImageNet
//! normalisation, network, bilinear resize back ([`preprocess`]).

pub mod checkpoint;
pub mod cubic;
pub mod dinov2;
pub mod dpt;
pub mod preprocess;
mod provider;
pub mod verify;

pub use provider::DepthAnythingV2Prior;

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dgstereo_core::Result;
use dgstereo_core::resample::resize_bilinear;
use serde::{Deserialize, Serialize};

use dinov2::{DinoVisionTransformer, IntermediateLayer, PATCH_SIZE, VitSpec};
use dpt::DptHead;

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

/// The encoder outputs and depth of one forward pass, for inspection and verification.
#[derive(Debug, Clone)]
pub struct DepthAnythingV2Output {
    /// The four normed intermediate layers the head reads.
    pub layers: Vec<IntermediateLayer>,
    /// Relative inverse depth, `[B, 1, H, W]`, non-negative.
    pub depth: Tensor<4>,
}

/// Depth Anything V2: a DINOv2 encoder and a DPT head.
#[derive(Module, Debug)]
pub struct DepthAnythingV2 {
    /// The ViT encoder (`pretrained.*`).
    pub pretrained: DinoVisionTransformer,
    /// The DPT head (`depth_head.*`).
    pub depth_head: DptHead,
    #[module(skip)]
    encoder: DepthAnythingV2Encoder,
}

impl DepthAnythingV2 {
    /// A randomly initialised model (for tests; real use loads a checkpoint).
    pub fn new(encoder: DepthAnythingV2Encoder, device: &Device) -> Self {
        let vit = encoder.vit();
        Self {
            pretrained: DinoVisionTransformer::new(vit, device),
            depth_head: DptHead::new(vit.embed_dim, encoder.features(), encoder.out_channels(), device),
            encoder,
        }
    }

    /// Builds a `encoder` model and loads an official checkpoint into it. Every key must match:
    /// a missing, unknown or mis-shaped key is an error that names it.
    pub fn load(encoder: DepthAnythingV2Encoder, weights: &Path, device: &Device) -> Result<Self> {
        let mut model = Self::new(encoder, device);
        checkpoint::load_into(&mut model, weights)?;
        Ok(model.no_grad())
    }

    /// Loads an official checkpoint, reading the encoder size from it.
    pub fn load_detect_encoder(weights: &Path, device: &Device) -> Result<Self> {
        let encoder = checkpoint::detect_encoder(weights)?;
        Self::load(encoder, weights, device)
    }

    /// The encoder size.
    pub fn encoder(&self) -> DepthAnythingV2Encoder {
        self.encoder
    }

    /// The network on normalised images, keeping the intermediate layers.
    ///
    /// # Shapes
    /// - `x`: `[B, 3, H, W]`, ImageNet-normalised, `H` and `W` multiples of 14
    /// - output depth: `[B, 1, H, W]`
    pub fn forward_with_layers(&self, x: Tensor<4>) -> DepthAnythingV2Output {
        let [_, _, h, w] = x.dims();
        assert!(
            h % PATCH_SIZE == 0 && w % PATCH_SIZE == 0,
            "Depth Anything V2 needs sides that are multiples of {PATCH_SIZE}, got {h}x{w}"
        );
        let grid = [h / PATCH_SIZE, w / PATCH_SIZE];
        let layers = self.pretrained.intermediate_layers(x, &self.encoder.intermediate_layers());
        let depth = self.depth_head.forward(&layers, grid);
        DepthAnythingV2Output { layers, depth }
    }

    /// The network on normalised images (`DepthAnythingV2.forward`, keeping the channel axis).
    ///
    /// # Shapes
    /// - `x`: `[B, 3, H, W]`, ImageNet-normalised, `H` and `W` multiples of 14
    /// - output: `[B, 1, H, W]`, relative inverse depth (larger = nearer), non-negative
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.forward_with_layers(x).depth
    }

    /// The official `infer_image` on a batch: preprocess, run, resize back to the image size.
    ///
    /// # Shapes
    /// - `images`: `[B, 3, H, W]`, RGB in 0..255
    /// - output: `[B, 1, H, W]`, relative inverse depth, non-negative
    pub fn infer(&self, images: Tensor<4>, input_size: usize) -> Tensor<4> {
        let [_, _, h, w] = images.dims();
        let x = preprocess::preprocess(images, input_size);
        resize_bilinear(self.forward(x), [h, w], true)
    }
}
