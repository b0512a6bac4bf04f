//! IGEV-Stereo's 2D convolution blocks (`BasicConv`, `BasicConv_IN`, `Conv2x`, `Conv2x_IN` of
//! its `submodule.py`, and the stems `stem_2`/`stem_4`/`spx_4`), with PyTorch's parameter names.
//!
//! They live here because two stages build them, the encoder (the feature pyramid and the image
//! stems) and the updater (the superpixel upsampling), and stages do not depend on each other.
//! Their convolutions are burn's own (this crate sits below the kernels).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::tensor::activation::{leaky_relu, relu};
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor};

use crate::batch_norm::FrozenBatchNorm;
use crate::tensor::instance_norm;

/// PyTorch's `nn.LeakyReLU()` slope.
const LEAKY_SLOPE: f64 = 0.01;
/// PyTorch's `InstanceNorm2d` epsilon.
const INSTANCE_EPS: f64 = 1e-5;

/// PyTorch's default initialisation of a convolution, `U(±1/sqrt(fan_in))`.
fn torch_default() -> Initializer {
    Initializer::KaimingUniform { gain: 1.0 / 3f64.sqrt(), fan_out_only: false }
}

/// A `k x k` convolution without bias (`nn.Conv2d(.., bias=False)`), symmetric padding `pad`.
pub fn conv2d_no_bias(channels: [usize; 2], kernel: usize, stride: usize, pad: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new(channels, [kernel, kernel])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_bias(false)
        .with_initializer(torch_default())
        .init(device)
}

/// The `4 x 4`, stride-2, padding-1 transposed convolution that doubles the resolution
/// (`nn.ConvTranspose2d(c_in, c_out, 4, 2, 1)`), with or without bias.
pub fn upsample_deconv(channels: [usize; 2], bias: bool, device: &Device) -> ConvTranspose2d {
    ConvTranspose2dConfig::new(channels, [4, 4])
        .with_stride([2, 2])
        .with_padding([1, 1])
        .with_bias(bias)
        .with_initializer(torch_default())
        .init(device)
}

/// Which normalisation a [`BasicConv`] applies after its convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockNorm {
    /// A frozen batch norm (`BasicConv`, its parameters under `bn`).
    Batch,
    /// Instance norm without parameters (`BasicConv_IN`).
    Instance,
}

/// The convolution of a [`BasicConv`]: plain, or transposed (`deconv=True`).
#[derive(Module, Debug)]
pub enum BlockConv {
    /// `nn.Conv2d`.
    Plain(Conv2d),
    /// `nn.ConvTranspose2d`.
    Transposed(ConvTranspose2d),
}

/// A convolution without bias, a batch or instance norm and a LeakyReLU (slope 0.01).
///
/// # Shapes
/// - input `[N, C_in, H, W]`; output `[N, C_out, H', W']` (the convolution's)
#[derive(Module, Debug)]
pub struct BasicConv {
    /// The convolution (`conv`).
    pub conv: BlockConv,
    /// The batch norm (`bn`); `None` for the instance-normed block, whose norm has no parameters.
    pub bn: Option<FrozenBatchNorm>,
    /// Whether an instance norm follows the convolution.
    pub instance_norm: bool,
}

impl BasicConv {
    /// A block with a plain `kernel x kernel` convolution (`stride`, `pad`), `norm` and a LeakyReLU.
    pub fn new(
        channels: [usize; 2],
        kernel: usize,
        stride: usize,
        pad: usize,
        norm: BlockNorm,
        device: &Device,
    ) -> Self {
        let conv = BlockConv::Plain(conv2d_no_bias(channels, kernel, stride, pad, device));
        Self::with_conv(conv, channels[1], norm, device)
    }

    /// A block with the resolution-doubling transposed convolution ([`upsample_deconv`]).
    pub fn upsampling(channels: [usize; 2], norm: BlockNorm, device: &Device) -> Self {
        Self::with_conv(BlockConv::Transposed(upsample_deconv(channels, false, device)), channels[1], norm, device)
    }

    fn with_conv(conv: BlockConv, out: usize, norm: BlockNorm, device: &Device) -> Self {
        Self {
            conv,
            bn: (norm == BlockNorm::Batch).then(|| FrozenBatchNorm::new(out, device)),
            instance_norm: norm == BlockNorm::Instance,
        }
    }

    /// Convolution, norm, LeakyReLU.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = match &self.conv {
            BlockConv::Plain(conv) => conv.forward(x),
            BlockConv::Transposed(conv) => conv.forward(x),
        };
        if let Some(bn) = &self.bn {
            x = bn.forward(x);
        }
        if self.instance_norm {
            x = instance_norm(x, INSTANCE_EPS);
        }
        leaky_relu(x, LEAKY_SLOPE)
    }
}

/// IGEV's `Conv2x` / `Conv2x_IN` with `deconv=True, concat=True`: a transposed convolution
/// doubles the resolution of `x` (then a nearest resize to the skip input's size where they
/// differ), the skip input `rem` is concatenated, and a 3x3 block mixes both.
///
/// # Shapes
/// - `x`: `[N, C_in, H, W]`, `rem`: `[N, C_out, H_r, W_r]` (about `2H x 2W`);
///   output `[N, 2·C_out, H_r, W_r]`
#[derive(Module, Debug)]
pub struct UpConcat {
    /// The upsampling block (`conv1`).
    pub conv1: BasicConv,
    /// The 3x3 block on the concatenation (`conv2`).
    pub conv2: BasicConv,
}

impl UpConcat {
    /// From `c_in` channels to `c_out` channels upsampled, `2·c_out` after the skip, with `norm`.
    pub fn new(c_in: usize, c_out: usize, norm: BlockNorm, device: &Device) -> Self {
        Self {
            conv1: BasicConv::upsampling([c_in, c_out], norm, device),
            conv2: BasicConv::new([2 * c_out, 2 * c_out], 3, 1, 1, norm, device),
        }
    }

    /// Upsamples `x`, concatenates `rem`, mixes.
    pub fn forward(&self, x: Tensor<4>, rem: Tensor<4>) -> Tensor<4> {
        let mut x = self.conv1.forward(x);
        let [_, _, h, w] = rem.dims();
        let [_, _, hx, wx] = x.dims();
        if [hx, wx] != [h, w] {
            x = interpolate(x, InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([h, w]));
        }
        self.conv2.forward(Tensor::cat(vec![x, rem], 1))
    }
}

/// A [`BasicConv`] with instance norm, then a 3x3 convolution without bias, an instance norm and
/// a ReLU: IGEV's `stem_2`, `stem_4` (stride 2) and `spx_4` (stride 1) `Sequential`s, whose
/// indices `0` and `1` are `block` and `conv` here.
///
/// # Shapes
/// - input `[N, C_in, H, W]`; output `[N, C_out, H/stride, W/stride]`
#[derive(Module, Debug)]
pub struct InstanceStem {
    /// The first block (`.0`).
    pub block: BasicConv,
    /// The second convolution (`.1`).
    pub conv: Conv2d,
}

impl InstanceStem {
    /// From `c_in` to `c_out` channels, the first convolution with `stride`.
    pub fn new(c_in: usize, c_out: usize, stride: usize, device: &Device) -> Self {
        Self {
            block: BasicConv::new([c_in, c_out], 3, stride, 1, BlockNorm::Instance, device),
            conv: conv2d_no_bias([c_out, c_out], 3, 1, 1, device),
        }
    }

    /// Both convolutions with their norms and activations.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(instance_norm(self.conv.forward(self.block.forward(x)), INSTANCE_EPS))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The upsampling block doubles the resolution and ends with twice its width; a skip input
    /// of another size decides the output's (the nearest resize of the reference).
    #[test]
    fn up_concat_takes_the_skip_inputs_size() {
        let device = crate::default_device();
        let block = UpConcat::new(6, 4, BlockNorm::Batch, &device);
        let x = Tensor::<4>::ones([1, 6, 3, 5], &device);
        assert_eq!(block.forward(x.clone(), Tensor::ones([1, 4, 6, 10], &device)).dims(), [1, 8, 6, 10]);
        assert_eq!(block.forward(x, Tensor::ones([1, 4, 7, 11], &device)).dims(), [1, 8, 7, 11]);
    }

    /// The instance stem halves the resolution with stride 2 and ends in a ReLU: nothing is
    /// negative.
    #[test]
    fn instance_stem_output_is_rectified() {
        let device = crate::default_device();
        let stem = InstanceStem::new(3, 8, 2, &device);
        let x = Tensor::<4>::random([1, 3, 16, 16], burn::tensor::Distribution::Uniform(-1.0, 1.0), &device);
        let y = stem.forward(x);
        assert_eq!(y.dims(), [1, 8, 8, 8]);
        assert!(y.min().into_scalar::<f32>() >= 0.0);
    }
}
