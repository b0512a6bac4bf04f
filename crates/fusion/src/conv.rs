//! The paper's "Depth+CNN" ablation: the image and depth features mixed by a plain 3x3 conv.

use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::{Device, Tensor};
use dgstereo_core::Result;
use dgstereo_kernels::{Numerics, conv2d_forward};

use crate::deformable::KERNEL;
use crate::init::{RGB, near_identity_conv};
use crate::projection::FeatureProjection;
use crate::{ImageFusion, missing_prior};

/// Depth+CNN fusion: [`crate::DeformableFusion`] with the deformable conv replaced by a plain one.
///
/// ```text
/// F_i = conv1x1(image), F_d = conv1x1(normalised depth)      [N, F, H, W]
/// out = conv3x3(cat(F_i, F_d))                               [N, 3, H, W]   padding 1
/// ```
///
/// Initialised like the deformable variant (near the identity, see [`crate::init`]); with the
/// same weights it equals the deformable variant whose offsets are all zero.
#[derive(Module, Debug)]
pub struct ConvFusion {
    /// The 1x1 image and depth projections.
    pub projection: FeatureProjection,
    /// 3x3 conv, `2F -> 3`, padding 1.
    pub mixer: Conv2d,
}

impl ConvFusion {
    /// Builds the module with `features` channels per branch.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] naming `features` when `features < 3`.
    pub fn new(features: usize, device: &Device) -> Result<Self> {
        let projection = FeatureProjection::new(features, device)?;
        let mixer = Conv2dConfig::new([2 * features, RGB], [KERNEL, KERNEL])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(device);
        Ok(Self { projection, mixer: near_identity_conv(mixer) })
    }

    /// The enhanced image.
    ///
    /// # Shapes
    /// - `image`: `[N, 3, H, W]`, 0..255
    /// - `depth`: `[N, 1, H_d, W_d]`, relative depth (normalised per image, resized if needed)
    /// - output: `[N, 3, H, W]`
    pub fn forward(&self, image: Tensor<4>, depth: Tensor<4>) -> Tensor<4> {
        let (image_features, depth_features) = self.projection.forward(image, depth);
        conv2d_forward(&self.mixer, Tensor::cat(vec![image_features, depth_features], 1), Numerics::Sensitive)
    }
}

impl ImageFusion for ConvFusion {
    fn fuse(&self, image: Tensor<4>, depth: Option<Tensor<4>>) -> Result<Tensor<4>> {
        let depth = depth.ok_or_else(|| missing_prior("conv"))?;
        Ok(self.forward(image, depth))
    }
}
