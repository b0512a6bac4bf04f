//! The Depth Anything V2 network: DINOv2 encoder, DPT head, and the official `infer_image`.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dgstereo_core::Result;
use dgstereo_kernels::resize_bilinear;

use super::dinov2::{DinoVisionTransformer, IntermediateLayer, PATCH_SIZE};
use super::dpt::DptHead;
use super::encoder::DepthAnythingV2Encoder;
use super::{checkpoint, preprocess};

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
        checkpoint::load_into(&mut model, encoder, weights)?;
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
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Shape`] for images that are not RGB or are empty
    /// ([`preprocess::preprocess`]).
    pub fn infer(&self, images: Tensor<4>, input_size: usize) -> dgstereo_core::Result<Tensor<4>> {
        let [_, _, h, w] = images.dims();
        let x = preprocess::preprocess(images, input_size)?;
        Ok(resize_bilinear(self.forward(x), [h, w], true))
    }
}
