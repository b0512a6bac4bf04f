//! IGEV-Stereo's convolution blocks: a convolution without bias, then a norm, then a leaky ReLU
//! (`BasicConv` with batch norm, `BasicConv_IN` with instance norm), in 2-D and 3-D, and the
//! frozen batch norm they use, with PyTorch's parameter names so official checkpoints load by
//! path.

use burn::module::{Module, Param};
use burn::nn::PaddingConfig2d;
use burn::nn::PaddingConfig3d;
use burn::nn::conv::{Conv2d, Conv2dConfig, Conv3d, Conv3dConfig, ConvTranspose3d, ConvTranspose3dConfig};
use burn::tensor::activation::leaky_relu;
use burn::tensor::{Device, Tensor};
use dgstereo_core::tensor::instance_norm;

/// PyTorch's `nn.LeakyReLU()` slope.
pub const LEAKY_SLOPE: f64 = 0.01;

/// PyTorch's norm epsilon.
const EPS: f64 = 1e-5;

/// BatchNorm in evaluation mode (IGEV-Stereo's `freeze_bn` and its evaluation), for any rank
/// `[N, C, ...]`: it normalises with its running statistics, which never update.
#[derive(Module, Debug)]
pub struct FrozenBatchNorm {
    /// Scale (`gamma`).
    pub weight: Param<Tensor<1>>,
    /// Shift (`beta`).
    pub bias: Param<Tensor<1>>,
    /// Running mean; not trained.
    pub running_mean: Param<Tensor<1>>,
    /// Running variance; not trained.
    pub running_var: Param<Tensor<1>>,
}

impl FrozenBatchNorm {
    /// A fresh layer: identity statistics, unit scale, zero shift.
    pub fn new(channels: usize, device: &Device) -> Self {
        let frozen = |t: Tensor<1>| Param::from_tensor(t).set_require_grad(false);
        Self {
            weight: Param::from_tensor(Tensor::ones([channels], device)),
            bias: Param::from_tensor(Tensor::zeros([channels], device)),
            running_mean: frozen(Tensor::zeros([channels], device)),
            running_var: frozen(Tensor::ones([channels], device)),
        }
    }

    /// `x · scale + shift` per channel (dimension 1), `scale = weight / sqrt(var + eps)` and
    /// `shift = bias - mean · scale`, as PyTorch's CPU inference kernel computes it.
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        let c = self.weight.dims()[0];
        let mut shape = [1; D];
        shape[1] = c;
        let scale = self.weight.val() / self.running_var.val().detach().add_scalar(EPS).sqrt();
        let shift = self.bias.val() - self.running_mean.val().detach() * scale.clone();
        x * scale.reshape(shape) + shift.reshape(shape)
    }
}

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

/// `BasicConv` (2-D): a convolution without bias, a batch norm, a leaky ReLU.
///
/// # Shapes
/// - input `[N, C_in, H, W]`; output `[N, C_out, H', W']`
#[derive(Module, Debug)]
pub struct BasicConv2d {
    /// The convolution.
    pub conv: Conv2d,
    /// The batch norm.
    pub bn: FrozenBatchNorm,
}

impl BasicConv2d {
    /// A `kernel²` convolution of `channels` (`[in, out]`), stride 1, with `padding`.
    pub fn new(channels: [usize; 2], kernel: usize, padding: usize, device: &Device) -> Self {
        Self {
            conv: conv2d_without_bias(channels, kernel, padding, device),
            bn: FrozenBatchNorm::new(channels[1], device),
        }
    }

    /// Convolution, batch norm, leaky ReLU.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        leaky_relu(self.bn.forward(self.conv.forward(x)), LEAKY_SLOPE)
    }
}

/// `BasicConv_IN` (2-D): a convolution without bias, an instance norm (no affine), a leaky ReLU.
///
/// # Shapes
/// - input `[N, C_in, H, W]`; output `[N, C_out, H', W']`
#[derive(Module, Debug)]
pub struct BasicConvIn2d {
    /// The convolution.
    pub conv: Conv2d,
}

impl BasicConvIn2d {
    /// A `kernel²` convolution of `channels` (`[in, out]`), stride 1, with `padding`.
    pub fn new(channels: [usize; 2], kernel: usize, padding: usize, device: &Device) -> Self {
        Self { conv: conv2d_without_bias(channels, kernel, padding, device) }
    }

    /// Convolution, instance norm, leaky ReLU.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        leaky_relu(instance_norm(self.conv.forward(x), EPS), LEAKY_SLOPE)
    }
}

/// A stride-1 2-D convolution without bias, PyTorch's default initialisation.
fn conv2d_without_bias(channels: [usize; 2], kernel: usize, padding: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new(channels, [kernel, kernel])
        .with_padding(PaddingConfig2d::Explicit(padding, padding, padding, padding))
        .with_bias(false)
        .init(device)
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};

    use super::*;

    /// The frozen norm is `(x - mean) / sqrt(var + eps) · weight + bias` per channel of a 5-D
    /// tensor, whatever its other dimensions.
    #[test]
    fn frozen_batch_norm_normalises_each_channel() {
        let device = default_device();
        let mut bn = FrozenBatchNorm::new(2, &device);
        bn.weight = Param::from_tensor(from_vec(vec![2.0, 0.5], [2], &device));
        bn.bias = Param::from_tensor(from_vec(vec![1.0, -1.0], [2], &device));
        bn.running_mean = Param::from_tensor(from_vec(vec![3.0, -2.0], [2], &device));
        bn.running_var = Param::from_tensor(from_vec(vec![4.0, 0.25], [2], &device));
        let x = Tensor::<5>::random([1, 2, 2, 1, 3], Distribution::Normal(0.0, 1.0), &device);
        let out = to_vec(bn.forward(x.clone()));
        for (i, v) in to_vec(x).into_iter().enumerate() {
            let c = i / 6;
            let (m, var, w, b) = [(3.0, 4.0, 2.0, 1.0), (-2.0, 0.25, 0.5, -1.0)][c];
            let expected = (v - m) / (var + 1e-5f32).sqrt() * w + b;
            assert!((out[i] - expected).abs() < 1e-5, "element {i}: {} vs {expected}", out[i]);
        }
    }

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
