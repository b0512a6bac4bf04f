//! IGEV-Stereo's feature network (`Feature`): a MobileNetV2 trunk and a decoder of upsampling
//! blocks with instance norm, giving a 4-level pyramid; and the image stems beside it.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::relu6;
use burn::tensor::{Device, Tensor};
use dgstereo_core::Probe;
use dgstereo_core::batch_norm::FrozenBatchNorm;
use dgstereo_core::conv_blocks::{BasicConv, BlockNorm, InstanceStem, UpConcat, conv2d_no_bias};

use crate::mobilenet::{DepthwiseSeparable, InvertedResidual, forward_stages, stage};

/// Widths of the pyramid, finest first: 1/4, 1/8, 1/16, 1/32 (before the 1/4 level is joined
/// with the image stem).
pub const PYRAMID_CHANNELS: [usize; 4] = [48, 64, 192, 160];
/// Width of the 1/4 image stem joined to the pyramid's finest level.
pub const STEM_4_CHANNELS: usize = 48;
/// Width of the 1/2 image stem.
pub const STEM_2_CHANNELS: usize = 32;

/// IGEV's `Feature`: timm `mobilenetv2_100`'s stem and stages sliced as `block0..block4`
/// (`blocks[0:1]`, `[1:2]`, `[2:3]`, `[3:5]`, `[5:6]`: 16 channels at 1/2, 24 at 1/4, 32 at 1/8,
/// 96 at 1/16, 160 at 1/32), then `deconv32_16`, `deconv16_8`, `deconv8_4` (transposed
/// convolution up, concatenation with the trunk's level, 3x3 block; instance norm) and `conv4`.
/// Every field is named as in the official state dict (`feature.block3.1.0.conv_pw.weight` is
/// `block3[1][0].conv_pw`).
///
/// # Shapes
/// - input `[N, 3, H, W]` (normalised to -1..1, `H` and `W` multiples of 32); output levels
///   `[N, PYRAMID_CHANNELS[l], H/2^(l+2), W/2^(l+2)]`
#[derive(Module, Debug)]
pub struct MobileNetPyramid {
    /// 3x3 stride-2 stem convolution.
    pub conv_stem: Conv2d,
    /// Its batch norm (ReLU6 follows).
    pub bn1: FrozenBatchNorm,
    /// Stage 0 (16 channels, 1/2).
    pub block0: Vec<Vec<DepthwiseSeparable>>,
    /// Stage 1 (24 channels, 1/4).
    pub block1: Vec<Vec<InvertedResidual>>,
    /// Stage 2 (32 channels, 1/8).
    pub block2: Vec<Vec<InvertedResidual>>,
    /// Stages 3 and 4 (64, then 96 channels, 1/16).
    pub block3: Vec<Vec<InvertedResidual>>,
    /// Stage 5 (160 channels, 1/32).
    pub block4: Vec<Vec<InvertedResidual>>,
    /// 1/32 to 1/16: 160 to 96, joined with the trunk's 96 (192).
    pub deconv32_16: UpConcat,
    /// 1/16 to 1/8: 192 to 32, joined with the trunk's 32 (64).
    pub deconv16_8: UpConcat,
    /// 1/8 to 1/4: 64 to 24, joined with the trunk's 24 (48).
    pub deconv8_4: UpConcat,
    /// 3x3 block at 1/4 (48 channels).
    pub conv4: BasicConv,
}

impl MobileNetPyramid {
    /// The network with fresh weights.
    pub fn new(device: &Device) -> Self {
        let instance = BlockNorm::Instance;
        Self {
            conv_stem: conv2d_no_bias([3, 32], 3, 2, 1, device),
            bn1: FrozenBatchNorm::new(32, device),
            block0: vec![vec![DepthwiseSeparable::new(32, 16, device)]],
            block1: vec![stage(16, 24, 2, 2, device)],
            block2: vec![stage(24, 32, 3, 2, device)],
            block3: vec![stage(32, 64, 4, 2, device), stage(64, 96, 3, 1, device)],
            block4: vec![stage(96, 160, 3, 2, device)],
            deconv32_16: UpConcat::new(160, 96, instance, device),
            deconv16_8: UpConcat::new(192, 32, instance, device),
            deconv8_4: UpConcat::new(64, 24, instance, device),
            conv4: BasicConv::new([48, 48], 3, 1, 1, instance, device),
        }
    }

    /// The pyramid of `image`, finest level first.
    pub fn forward(&self, image: Tensor<4>) -> [Tensor<4>; 4] {
        let x = relu6(self.bn1.forward(self.conv_stem.forward(image)));
        let x2 = self.block0.iter().flatten().fold(x, |x, block| block.forward(x));
        let x4 = forward_stages(&self.block1, x2);
        let x8 = forward_stages(&self.block2, x4.clone());
        let x16 = forward_stages(&self.block3, x8.clone());
        let x32 = forward_stages(&self.block4, x16.clone());
        let x16 = self.deconv32_16.forward(x32.clone(), x16);
        let x8 = self.deconv16_8.forward(x16.clone(), x8);
        let x4 = self.conv4.forward(self.deconv8_4.forward(x8.clone(), x4));
        [x4, x8, x16, x32]
    }
}

/// A view's features as IGEV's cost volume and upsampling read them.
///
/// # Shapes
/// - `levels[0]`: `[N, 96, H/4, W/4]` (the pyramid's 48 channels, then `stem_4`'s 48);
///   `levels[l]`, `l = 1..3`: `[N, PYRAMID_CHANNELS[l], H/2^(l+2), W/2^(l+2)]`
/// - `stem_2`: `[N, 32, H/2, W/2]`
#[derive(Debug, Clone)]
pub struct FeaturePyramid {
    /// The levels, finest first.
    pub levels: Vec<Tensor<4>>,
    /// The 1/2 image stem.
    pub stem_2: Tensor<4>,
}

impl FeaturePyramid {
    /// Records the pyramid of the view `side` (`left`, `right`) under the reference's module
    /// outputs: `feature.{side}.{l}` (the finest level without the stem's channels),
    /// `stem_2.{side}`, `stem_4.{side}`.
    pub fn record(&self, side: &str, probe: &mut Probe<'_>) {
        let finest = &self.levels[0];
        let pyramid_channels = finest.dims()[1] - STEM_4_CHANNELS;
        probe.record(format_args!("feature.{side}.0"), &finest.clone().narrow(1, 0, pyramid_channels));
        for (l, level) in self.levels.iter().enumerate().skip(1) {
            probe.record(format_args!("feature.{side}.{l}"), level);
        }
        probe.record(format_args!("stem_2.{side}"), &self.stem_2);
        probe.record(format_args!("stem_4.{side}"), &finest.clone().narrow(1, pyramid_channels, STEM_4_CHANNELS));
    }
}

/// IGEV's `stem_2` (3 to 32 channels at 1/2, fresh weights).
pub fn stem_2(device: &Device) -> InstanceStem {
    InstanceStem::new(3, STEM_2_CHANNELS, 2, device)
}

/// IGEV's `stem_4` (32 to 48 channels at 1/4, on `stem_2`'s output; fresh weights).
pub fn stem_4(device: &Device) -> InstanceStem {
    InstanceStem::new(STEM_2_CHANNELS, STEM_4_CHANNELS, 2, device)
}

/// The pyramid of one view with its stems joined (`features[0] = cat(features[0], stem_4x)`).
pub fn feature_pyramid(
    feature: &MobileNetPyramid,
    [stem_2, stem_4]: [&InstanceStem; 2],
    image: Tensor<4>,
) -> FeaturePyramid {
    let [x4, x8, x16, x32] = feature.forward(image.clone());
    let stem_2x = stem_2.forward(image);
    let stem_4x = stem_4.forward(stem_2x.clone());
    FeaturePyramid { levels: vec![Tensor::cat(vec![x4, stem_4x], 1), x8, x16, x32], stem_2: stem_2x }
}
