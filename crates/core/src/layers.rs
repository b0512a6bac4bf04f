//! Constructors of the plain layers every stage uses.

use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::tensor::Device;

/// How a convolution's weights start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConvInit {
    /// PyTorch's default (`kaiming_uniform_(a=sqrt(5))`, i.e. U(±1/sqrt(fan_in))).
    TorchDefault,
    /// Kaiming-normal for ReLU, fan-out mode, as RAFT-Stereo's encoders.
    KaimingFanOut,
}

/// A `k x k` convolution with symmetric padding `pad` and a bias, as `nn.Conv2d`.
pub fn conv2d(
    channels: [usize; 2],
    kernel: usize,
    stride: usize,
    pad: usize,
    init: ConvInit,
    device: &Device,
) -> Conv2d {
    let initializer = match init {
        ConvInit::TorchDefault => Initializer::KaimingUniform { gain: 1.0 / 3f64.sqrt(), fan_out_only: false },
        ConvInit::KaimingFanOut => Initializer::KaimingNormal { gain: 2f64.sqrt(), fan_out_only: true },
    };
    Conv2dConfig::new(channels, [kernel, kernel])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_initializer(initializer)
        .init(device)
}
