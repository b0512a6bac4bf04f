//! The feature encoder (`fnet`, the reference's `BasicEncoder`).

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::{Numerics, conv2d_forward};

use crate::depth_block::DepthFeatureBlock;
use crate::norm::{Norm, NormKind};
use crate::residual::{ResidualBlock, forward_layer, make_layer};

/// The strides of the trunk's conv1, layer2 and layer3 for `n_downsample` (the reference's
/// `1 + (downsample > 2)`, `1 + (downsample > 1)`, `1 + (downsample > 0)`).
pub(crate) fn trunk_strides(n_downsample: usize) -> [usize; 3] {
    [1 + (n_downsample > 2) as usize, 1 + (n_downsample > 1) as usize, 1 + (n_downsample > 0) as usize]
}

/// Matching features at `1/2^n_downsample` resolution: a residual trunk and a 1x1 projection.
///
/// # Shapes
/// - input `[N, 3, H, W]` (normalised to -1..1), output `[N, output_dim, H/f, W/f]`
#[derive(Module, Debug)]
pub struct FeatureEncoder {
    /// 7x7 stem convolution.
    pub conv1: Conv2d,
    /// Norm of the stem.
    pub norm1: Norm,
    /// `trunk[0]` channels (64), full stem resolution.
    pub layer1: Vec<ResidualBlock>,
    /// `trunk[1]` channels (96).
    pub layer2: Vec<ResidualBlock>,
    /// `trunk[2]` channels (128).
    pub layer3: Vec<ResidualBlock>,
    /// The monocular features' block added to the trunk's output (DEFOM-Stereo's `convd`).
    pub convd: Option<DepthFeatureBlock>,
    /// 1x1 projection to `output_dim`.
    pub conv2: Conv2d,
}

impl FeatureEncoder {
    /// The encoder with `output_dim` channels (256 in RAFT-Stereo), trunk widths `trunk`
    /// (`[64, 96, 128]` in RAFT-Stereo) and `norm` (instance); with `depth_channels`, it adds
    /// monocular features of that width to its trunk's output ([`DepthFeatureBlock`]).
    pub fn new(
        output_dim: usize,
        trunk: [usize; 3],
        norm: NormKind,
        n_downsample: usize,
        depth_channels: Option<usize>,
        device: &Device,
    ) -> Self {
        let [s1, s2, s3] = trunk_strides(n_downsample);
        let [c1, c2, c3] = trunk;
        let init = ConvInit::KaimingFanOut;
        Self {
            conv1: conv2d([3, c1], 7, s1, 3, init, device),
            norm1: norm.init(c1, device),
            layer1: make_layer(c1, c1, norm, 1, device),
            layer2: make_layer(c1, c2, norm, s2, device),
            layer3: make_layer(c2, c3, norm, s3, device),
            convd: depth_channels.map(|d| DepthFeatureBlock::new(d, c3, norm, device)),
            conv2: conv2d([c3, output_dim], 1, 1, 0, init, device),
        }
    }

    /// Matching features of `images`, with the monocular features `depth` (`[N, D, H/f, W/f]`)
    /// added after the trunk where the encoder has a [`DepthFeatureBlock`] (`depth` is then
    /// required; it is ignored otherwise).
    pub fn features_with_depth(&self, images: Tensor<4>, depth: Option<Tensor<4>>) -> Tensor<4> {
        // Instance norms follow its layers: they magnify a change of rounding.
        let numerics = Numerics::Sensitive;
        let x = self.norm1.conv_forward_relu(&self.conv1, images, true, numerics);
        let x = forward_layer(&self.layer1, x, numerics);
        let x = forward_layer(&self.layer2, x, numerics);
        let mut x = forward_layer(&self.layer3, x, numerics);
        if let (Some(block), Some(depth)) = (&self.convd, depth) {
            x = x + block.forward(depth, numerics);
        }
        conv2d_forward(&self.conv2, x, numerics)
    }

    /// Matching features of `images` (`[N, 3, H, W]`, normalised to -1..1) without monocular
    /// features, `[N, C, H/f, W/f]`.
    pub fn features(&self, images: Tensor<4>) -> Tensor<4> {
        self.features_with_depth(images, None)
    }
}

/// The feature head of the shared-backbone variant (the reference's top-level `conv2`):
/// a residual block with instance norm and a 3x3 convolution to 256 channels, applied to the
/// context trunk's output.
#[derive(Module, Debug)]
pub struct SharedFeatureHead {
    /// Residual block (`conv2.0`).
    pub block: ResidualBlock,
    /// 3x3 projection (`conv2.1`).
    pub conv: Conv2d,
}

impl SharedFeatureHead {
    /// The head from `trunk_dim` trunk channels (128) to `output_dim`.
    pub fn new(trunk_dim: usize, output_dim: usize, device: &Device) -> Self {
        Self {
            block: ResidualBlock::new(trunk_dim, trunk_dim, NormKind::Instance, 1, device),
            conv: conv2d([trunk_dim, output_dim], 3, 1, 1, ConvInit::TorchDefault, device),
        }
    }

    /// Features from the trunk output `[N, 128, H, W]`.
    pub fn forward(&self, trunk: Tensor<4>) -> Tensor<4> {
        conv2d_forward(&self.conv, self.block.forward(trunk, Numerics::Sensitive), Numerics::Sensitive)
    }
}
