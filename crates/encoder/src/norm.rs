//! The normalisations of RAFT-Stereo's encoders, with PyTorch's parameter names.

use burn::module::{Module, Param};
use burn::nn::Identity;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
pub use dgstereo_core::batch_norm::FrozenBatchNorm;
use dgstereo_core::tensor::instance_norm;
use dgstereo_kernels::{Normalization, Numerics, affine_planes, conv2d_affine, conv2d_forward, normalize_planes};
use serde::{Deserialize, Serialize};

const EPS: f64 = 1e-5;

/// Which normalisation a residual block uses (`norm_fn` of the reference).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum NormKind {
    /// BatchNorm, frozen: it always normalises with its running statistics.
    #[default]
    Batch,
    /// GroupNorm with `channels / 8` groups.
    Group,
    /// InstanceNorm without affine parameters.
    Instance,
    /// No normalisation.
    None,
}

/// A normalisation layer, chosen by [`NormKind`].
#[derive(Module, Debug)]
pub enum Norm {
    /// Frozen BatchNorm.
    Batch(FrozenBatchNorm),
    /// GroupNorm.
    Group(GroupNorm),
    /// InstanceNorm (no parameters).
    Instance(InstanceNorm),
    /// Identity.
    None(Identity),
}

impl NormKind {
    /// Builds the layer for `channels` channels.
    pub fn init(self, channels: usize, device: &Device) -> Norm {
        match self {
            Self::Batch => Norm::Batch(FrozenBatchNorm::new(channels, device)),
            Self::Group => Norm::Group(GroupNorm::new(channels / 8, channels, device)),
            Self::Instance => Norm::Instance(InstanceNorm { epsilon: EPS }),
            Self::None => Norm::None(Identity::new()),
        }
    }
}

impl Norm {
    /// Normalises `[N, C, H, W]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Batch(n) => n.forward(x),
            Self::Group(n) => n.forward(x),
            Self::Instance(n) => n.forward(x),
            Self::None(_) => x,
        }
    }

    /// `conv` (with the rounding `numerics` allows in training), then this norm, then a ReLU
    /// when `relu_after`. A frozen batch norm goes to the kernels with the convolution
    /// ([`conv2d_affine`]: CPU inference folds it in, so the host convolution writes the
    /// normalised and rectified output at once); the other norms follow the convolution
    /// ([`forward_relu`](Self::forward_relu)).
    ///
    /// # Shapes
    /// - `x`: `[N, C_in, H, W]`; output `[N, C_out, H_out, W_out]`
    pub fn conv_forward_relu(&self, conv: &Conv2d, x: Tensor<4>, relu_after: bool, numerics: Numerics) -> Tensor<4> {
        match self {
            Self::Batch(bn) => {
                let (scale, shift) = bn.scale_shift();
                conv2d_affine(conv, x, [scale, shift], relu_after, numerics)
            }
            _ => self.forward_relu(conv2d_forward(conv, x, numerics), relu_after),
        }
    }

    /// [`forward`](Self::forward), then a ReLU when `relu_after`: the batch, instance and no
    /// norm as the kernels' operations ([`affine_planes`], [`normalize_planes`]: one parallel host
    /// pass with the ReLU for CPU inference), the group norm in tensor operations.
    ///
    /// # Shapes
    /// - `x`: `[N, C, H, W]`; output: the same
    pub fn forward_relu(&self, x: Tensor<4>, relu_after: bool) -> Tensor<4> {
        match self {
            Self::Batch(n) => {
                let (scale, shift) = n.scale_shift();
                affine_planes(x, scale, shift, relu_after)
            }
            Self::Instance(n) => normalize_planes(x, Normalization::Instance { epsilon: n.epsilon }, relu_after),
            Self::None(_) if !relu_after => x,
            Self::None(_) => normalize_planes(x, Normalization::Identity, true),
            Self::Group(n) => {
                let y = n.forward(x);
                if relu_after { dgstereo_kernels::rectify(y) } else { y }
            }
        }
    }
}

/// GroupNorm with affine parameters (PyTorch names).
#[derive(Module, Debug)]
pub struct GroupNorm {
    /// Scale.
    pub weight: Param<Tensor<1>>,
    /// Shift.
    pub bias: Param<Tensor<1>>,
    /// Number of groups.
    pub groups: usize,
    /// Added to the variance.
    pub epsilon: f64,
}

impl GroupNorm {
    /// A fresh layer with unit scale and zero shift.
    pub fn new(groups: usize, channels: usize, device: &Device) -> Self {
        Self {
            weight: Param::from_tensor(Tensor::ones([channels], device)),
            bias: Param::from_tensor(Tensor::zeros([channels], device)),
            groups: groups.max(1),
            epsilon: EPS,
        }
    }

    /// Normalises `[N, C, H, W]` over each group of channels and all pixels.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [n, c, h, w] = x.dims();
        let g = self.groups;
        let xg = x.reshape([n, g, (c / g) * h * w]);
        let mean = xg.clone().mean_dim(2);
        let centred = xg - mean;
        let var = centred.clone().square().mean_dim(2);
        let y = (centred / var.add_scalar(self.epsilon).sqrt()).reshape([n, c, h, w]);
        y * self.weight.val().reshape([1, c, 1, 1]) + self.bias.val().reshape([1, c, 1, 1])
    }
}

/// InstanceNorm2d without affine parameters (PyTorch's default), biased variance.
#[derive(Module, Debug)]
pub struct InstanceNorm {
    /// Added to the variance.
    pub epsilon: f64,
}

impl InstanceNorm {
    /// Normalises each channel of each image over its pixels.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        instance_norm(x, self.epsilon)
    }
}
