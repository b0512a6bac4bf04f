//! RAFT-Stereo's residual block.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::{Numerics, add_relu};

use crate::norm::{Norm, NormKind};

/// Two 3x3 convolutions with normalisation and a (projected) skip connection.
///
/// `y = ReLU(N1(conv1(x)))`, `y = ReLU(N2(conv2(y)))`, `x = N3(conv1x1(x))` when the stride or
/// the width changes, output `ReLU(x + y)`. Field names follow the reference's state dict; its
/// `downsample.1` is the same module as `norm3` and is loaded from `norm3`.
///
/// # Shapes
/// - input `[N, C_in, H, W]`, output `[N, C_out, H/stride, W/stride]`
#[derive(Module, Debug)]
pub struct ResidualBlock {
    /// First 3x3 convolution (carries the stride).
    pub conv1: Conv2d,
    /// Second 3x3 convolution.
    pub conv2: Conv2d,
    /// Norm after `conv1`.
    pub norm1: Norm,
    /// Norm after `conv2`.
    pub norm2: Norm,
    /// Norm of the projected skip connection.
    pub norm3: Option<Norm>,
    /// 1x1 projection of the skip connection (`downsample.0` in the reference).
    pub downsample: Option<Conv2d>,
}

impl ResidualBlock {
    /// A block from `in_planes` to `planes` channels with `stride`.
    pub fn new(in_planes: usize, planes: usize, norm: NormKind, stride: usize, device: &Device) -> Self {
        let project = stride != 1 || in_planes != planes;
        let init = ConvInit::KaimingFanOut;
        Self {
            conv1: conv2d([in_planes, planes], 3, stride, 1, init, device),
            conv2: conv2d([planes, planes], 3, 1, 1, init, device),
            norm1: norm.init(planes, device),
            norm2: norm.init(planes, device),
            norm3: project.then(|| norm.init(planes, device)),
            downsample: project.then(|| conv2d([in_planes, planes], 1, stride, 0, init, device)),
        }
    }

    /// Applies the block, its convolutions with the rounding `numerics` allows in training.
    pub fn forward(&self, x: Tensor<4>, numerics: Numerics) -> Tensor<4> {
        let y = self.norm1.conv_forward_relu(&self.conv1, x.clone(), true, numerics);
        let y = self.norm2.conv_forward_relu(&self.conv2, y, true, numerics);
        let x = match (&self.downsample, &self.norm3) {
            (Some(conv), Some(norm)) => norm.conv_forward_relu(conv, x, false, numerics),
            _ => x,
        };
        add_relu(x, y)
    }
}

/// Two residual blocks, the first with `stride` (`_make_layer` of the reference).
pub fn make_layer(
    in_planes: usize,
    planes: usize,
    norm: NormKind,
    stride: usize,
    device: &Device,
) -> Vec<ResidualBlock> {
    vec![
        ResidualBlock::new(in_planes, planes, norm, stride, device),
        ResidualBlock::new(planes, planes, norm, 1, device),
    ]
}

/// Applies a sequence of blocks, with the rounding `numerics` allows in training.
pub fn forward_layer(blocks: &[ResidualBlock], mut x: Tensor<4>, numerics: Numerics) -> Tensor<4> {
    for b in blocks {
        x = b.forward(x, numerics);
    }
    x
}
