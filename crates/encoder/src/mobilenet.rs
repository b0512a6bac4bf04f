//! The MobileNetV2 trunk of IGEV-Stereo's feature network: timm's `mobilenetv2_100` (timm 0.5.4
//! module layout) up to its 1/32 stage, with timm's parameter names.

use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::activation::relu6;
use burn::tensor::{Device, Tensor};
use dgstereo_core::batch_norm::FrozenBatchNorm;
use dgstereo_core::conv_blocks::conv2d_no_bias;

/// The expansion of every inverted residual of `mobilenetv2_100`.
const EXPANSION: usize = 6;

/// A depthwise `3 x 3` convolution without bias over `channels` channels.
fn depthwise(channels: usize, stride: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([channels, channels], [3, 3])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .with_groups(channels)
        .with_bias(false)
        .init(device)
}

/// timm's `DepthwiseSeparableConv` (the first stage, `ds_r1_k3_s1_c16`): a depthwise 3x3
/// convolution, batch norm and ReLU6, then a pointwise projection with batch norm and no
/// activation; no skip (its widths differ).
///
/// # Shapes
/// - input `[N, C_in, H, W]`; output `[N, C_out, H, W]`
#[derive(Module, Debug)]
pub struct DepthwiseSeparable {
    /// Depthwise 3x3 convolution.
    pub conv_dw: Conv2d,
    /// Its batch norm.
    pub bn1: FrozenBatchNorm,
    /// Pointwise projection.
    pub conv_pw: Conv2d,
    /// Its batch norm.
    pub bn2: FrozenBatchNorm,
}

impl DepthwiseSeparable {
    /// From `c_in` to `c_out` channels at stride 1.
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv_dw: depthwise(c_in, 1, device),
            bn1: FrozenBatchNorm::new(c_in, device),
            conv_pw: conv2d_no_bias([c_in, c_out], 1, 1, 0, device),
            bn2: FrozenBatchNorm::new(c_out, device),
        }
    }

    /// Applies the block.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = relu6(self.bn1.forward(self.conv_dw.forward(x)));
        self.bn2.forward(self.conv_pw.forward(x))
    }
}

/// timm's `InvertedResidual`: a pointwise expansion (x6), a depthwise 3x3 convolution carrying
/// the stride, each with batch norm and ReLU6, and a linear pointwise projection with batch
/// norm; the input is added where the stride is 1 and the widths agree.
///
/// # Shapes
/// - input `[N, C_in, H, W]`; output `[N, C_out, H/stride, W/stride]`
#[derive(Module, Debug)]
pub struct InvertedResidual {
    /// Pointwise expansion.
    pub conv_pw: Conv2d,
    /// Its batch norm.
    pub bn1: FrozenBatchNorm,
    /// Depthwise 3x3 convolution.
    pub conv_dw: Conv2d,
    /// Its batch norm.
    pub bn2: FrozenBatchNorm,
    /// Linear pointwise projection.
    pub conv_pwl: Conv2d,
    /// Its batch norm.
    pub bn3: FrozenBatchNorm,
    /// Whether the input is added to the output.
    pub residual: bool,
}

impl InvertedResidual {
    /// From `c_in` to `c_out` channels with `stride`.
    pub fn new(c_in: usize, c_out: usize, stride: usize, device: &Device) -> Self {
        let mid = c_in * EXPANSION;
        Self {
            conv_pw: conv2d_no_bias([c_in, mid], 1, 1, 0, device),
            bn1: FrozenBatchNorm::new(mid, device),
            conv_dw: depthwise(mid, stride, device),
            bn2: FrozenBatchNorm::new(mid, device),
            conv_pwl: conv2d_no_bias([mid, c_out], 1, 1, 0, device),
            bn3: FrozenBatchNorm::new(c_out, device),
            residual: stride == 1 && c_in == c_out,
        }
    }

    /// Applies the block.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = relu6(self.bn1.forward(self.conv_pw.forward(x.clone())));
        let y = relu6(self.bn2.forward(self.conv_dw.forward(y)));
        let y = self.bn3.forward(self.conv_pwl.forward(y));
        if self.residual { y + x } else { y }
    }
}

/// One timm stage: `repeats` inverted residuals, the first from `c_in` with `stride`.
pub fn stage(c_in: usize, c_out: usize, repeats: usize, stride: usize, device: &Device) -> Vec<InvertedResidual> {
    (0..repeats)
        .map(|i| {
            if i == 0 {
                InvertedResidual::new(c_in, c_out, stride, device)
            } else {
                InvertedResidual::new(c_out, c_out, 1, device)
            }
        })
        .collect()
}

/// Applies a sequence of stages.
pub fn forward_stages(stages: &[Vec<InvertedResidual>], mut x: Tensor<4>) -> Tensor<4> {
    for block in stages.iter().flatten() {
        x = block.forward(x);
    }
    x
}
