//! IGEV-Stereo's 3-D convolution blocks (`BasicConv(is_3d=True)`): a convolution or transposed
//! convolution without bias, then a batch norm, then a leaky ReLU, with PyTorch's parameter names
//! so official checkpoints load by path. The 2-D blocks are the core crate's
//! ([`dgstereo_core::conv_blocks`]), which the encoder and updater share.

use burn::module::Module;
use burn::nn::PaddingConfig3d;
use burn::nn::conv::{Conv3d, Conv3dConfig, ConvTranspose3d, ConvTranspose3dConfig};
use burn::tensor::activation::leaky_relu;
use burn::tensor::{Device, Tensor};
use dgstereo_core::batch_norm::FrozenBatchNorm;

/// PyTorch's `nn.LeakyReLU()` slope.
pub const LEAKY_SLOPE: f64 = 0.01;

/// `BasicConv(is_3d=True)`: a 3-D convolution without bias, a batch norm and a leaky ReLU, each
/// of the last two optional (`bn`, `relu`). The norm's tensors exist whether it is used or not,
/// as in the reference's state dict.
///
/// # Shapes
/// - input `[N, C_in, D, H, W]`; output `[N, C_out, D', H', W']`
#[derive(Module, Debug)]
pub struct BasicConv3d {
    /// The convolution.
    pub conv: Conv3d,
    /// The batch norm.
    pub bn: FrozenBatchNorm,
    /// Whether the batch norm applies.
    pub use_bn: bool,
    /// Whether the leaky ReLU applies.
    pub relu: bool,
}

impl BasicConv3d {
    /// A `kernel³` convolution of `channels` (`[in, out]`) with `stride` and `padding`, batch
    /// norm and leaky ReLU.
    pub fn new(channels: [usize; 2], kernel: usize, stride: usize, padding: usize, device: &Device) -> Self {
        let conv = Conv3dConfig::new(channels, [kernel; 3])
            .with_stride([stride; 3])
            .with_padding(PaddingConfig3d::Explicit(padding, padding, padding))
            .with_bias(false)
            .init(device);
        Self { conv, bn: FrozenBatchNorm::new(channels[1], device), use_bn: true, relu: true }
    }

    /// Convolution, then the norm and the activation where they apply.
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let x = self.conv.forward(x);
        let x = if self.use_bn { self.bn.forward(x) } else { x };
        if self.relu { leaky_relu(x, LEAKY_SLOPE) } else { x }
    }
}

/// `BasicConv(deconv=True, is_3d=True)`: a transposed 3-D convolution (kernel 4, stride 2,
/// padding 1: twice the size) without bias, then the optional batch norm and leaky ReLU.
///
/// # Shapes
/// - input `[N, C_in, D, H, W]`; output `[N, C_out, 2D, 2H, 2W]`
#[derive(Module, Debug)]
pub struct BasicDeconv3d {
    /// The transposed convolution.
    pub conv: ConvTranspose3d,
    /// The batch norm.
    pub bn: FrozenBatchNorm,
    /// Whether the batch norm applies.
    pub use_bn: bool,
    /// Whether the leaky ReLU applies.
    pub relu: bool,
}

impl BasicDeconv3d {
    /// The doubling transposed convolution of `channels` (`[in, out]`), with the batch norm and
    /// leaky ReLU when `activated` (the last one of the hourglass has neither).
    pub fn new(channels: [usize; 2], activated: bool, device: &Device) -> Self {
        let conv = ConvTranspose3dConfig::new(channels, [4; 3])
            .with_stride([2; 3])
            .with_padding([1; 3])
            .with_bias(false)
            .init(device);
        Self { conv, bn: FrozenBatchNorm::new(channels[1], device), use_bn: activated, relu: activated }
    }

    /// Transposed convolution, then the norm and the activation where they apply.
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let x = self.conv.forward(x);
        let x = if self.use_bn { self.bn.forward(x) } else { x };
        if self.relu { leaky_relu(x, LEAKY_SLOPE) } else { x }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::{max_abs_diff, to_vec};

    use super::*;

    /// The transposed convolution doubles every dimension, and without its norm and activation
    /// it is linear (negative outputs survive).
    #[test]
    fn deconvolution_doubles_the_volume() {
        let device = default_device();
        let deconv = BasicDeconv3d::new([4, 2], false, &device);
        let x = Tensor::<5>::random([1, 4, 3, 5, 6], Distribution::Normal(0.0, 1.0), &device);
        let y = deconv.forward(x.clone());
        assert_eq!(y.dims(), [1, 2, 6, 10, 12]);
        let doubled = deconv.forward(x.mul_scalar(2.0));
        assert!(max_abs_diff(doubled, y.clone().mul_scalar(2.0)) < 1e-4);
        assert!(to_vec(y).iter().any(|v| *v < -1e-3));
        let activated = BasicDeconv3d::new([4, 2], true, &device);
        let z = to_vec(activated.forward(Tensor::random([1, 4, 2, 2, 2], Distribution::Normal(0.0, 1.0), &device)));
        // A leaky ReLU after a unit-statistics norm: negatives shrink to a hundredth.
        assert!(z.iter().all(|v| *v > -0.2), "{z:?}");
    }
}
