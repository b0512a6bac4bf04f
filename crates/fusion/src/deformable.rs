//! DGIA, depth-guided image augmentation: a deformable convolution whose sampling offsets come
//! from the depth prior.

use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig, DeformConv2d, DeformConv2dConfig};
use burn::tensor::{Device, Tensor};
use dgstereo_core::Result;
use dgstereo_kernels::deform_conv2d_forward;
use dgstereo_kernels::{Numerics, conv2d_forward};

use crate::init::{RGB, near_identity_deform_conv, zeroed};
use crate::projection::FeatureProjection;
use crate::{ImageFusion, missing_prior};

/// Side of the deformable kernel.
pub const KERNEL: usize = 3;

/// Depth-guided image augmentation (the paper's DGIA).
///
/// ```text
/// F_i    = conv1x1(image)                      [N, F, H, W]
/// F_d    = conv1x1(normalised depth)           [N, F, H, W]
/// offset = conv3x3(F_d)                        [N, 2*3*3, H, W]   (dy, dx) per tap, torchvision order
/// out    = deform_conv3x3(cat(F_i, F_d), offset)   [N, 3, H, W]   padding 1, no modulation mask
/// ```
///
/// One module serves both views (shared weights); every image of a batch is processed
/// independently, so the two views may be fused one at a time or stacked in one batch. The output
/// is not clamped to 0..255. At initialisation the output is close to the input image
/// (see [`crate::init`]).
#[derive(Module, Debug)]
pub struct DeformableFusion {
    /// The 1x1 image and depth projections.
    pub projection: FeatureProjection,
    /// 3x3 conv, `F -> 18`, padding 1: the deformable kernel's offsets from `F_d`. Zero at init.
    pub offset: Conv2d,
    /// 3x3 deformable conv, `2F -> 3`, padding 1.
    pub mixer: DeformConv2d,
}

impl DeformableFusion {
    /// Builds the module with `features` channels per branch (`F`, the paper uses 8).
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] naming `features` when `features < 3`.
    pub fn new(features: usize, device: &Device) -> Result<Self> {
        let projection = FeatureProjection::new(features, device)?;
        let offset = Conv2dConfig::new([features, 2 * KERNEL * KERNEL], [KERNEL, KERNEL])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(device);
        let mixer = DeformConv2dConfig::new([2 * features, RGB], [KERNEL, KERNEL])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(device);
        Ok(Self { projection, offset: zeroed(offset), mixer: near_identity_deform_conv(mixer) })
    }

    /// The sampling offsets predicted from the depth features.
    ///
    /// # Shapes
    /// - `depth_features`: `[N, F, H, W]`
    /// - output: `[N, 18, H, W]`
    pub fn offsets(&self, depth_features: Tensor<4>) -> Tensor<4> {
        conv2d_forward(&self.offset, depth_features, Numerics::Sensitive)
    }

    /// The enhanced image.
    ///
    /// # Shapes
    /// - `image`: `[N, 3, H, W]`, 0..255
    /// - `depth`: `[N, 1, H_d, W_d]`, relative depth in any scale (normalised per image; resized
    ///   bilinearly when its size differs from the image's)
    /// - output: `[N, 3, H, W]`
    pub fn forward(&self, image: Tensor<4>, depth: Tensor<4>) -> Tensor<4> {
        let (image_features, depth_features) = self.projection.forward(image, depth);
        let offset = self.offsets(depth_features.clone());
        let features = Tensor::cat(vec![image_features, depth_features], 1);
        deform_conv2d_forward(&self.mixer, features, offset)
    }
}

impl ImageFusion for DeformableFusion {
    fn fuse(&self, image: Tensor<4>, depth: Option<Tensor<4>>) -> Result<Tensor<4>> {
        let depth = depth.ok_or_else(|| missing_prior("deformable"))?;
        Ok(self.forward(image, depth))
    }
}
