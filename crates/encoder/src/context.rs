//! The context encoder (`cnet`, the reference's `MultiBasicEncoder`).

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::{Numerics, conv2d_forward};

use crate::ContextFeatures;
use crate::depth_block::DepthFeatureBlock;
use crate::feature::trunk_strides;
use crate::norm::{Norm, NormKind};
use crate::residual::{ResidualBlock, forward_layer, make_layer};

/// A head of the 1/4 and 1/8 levels: a residual block and a 3x3 convolution
/// (`outputsXX.j.0` and `outputsXX.j.1` in the reference).
#[derive(Module, Debug)]
pub struct ContextHead {
    /// Residual block.
    pub block: ResidualBlock,
    /// 3x3 convolution to the head's width.
    pub conv: Conv2d,
}

impl ContextHead {
    fn new(trunk_dim: usize, dim: usize, norm: NormKind, device: &Device) -> Self {
        Self {
            block: ResidualBlock::new(trunk_dim, trunk_dim, norm, 1, device),
            conv: conv2d([trunk_dim, dim], 3, 1, 1, ConvInit::KaimingFanOut, device),
        }
    }

    fn forward(&self, x: Tensor<4>, numerics: Numerics) -> Tensor<4> {
        conv2d_forward(&self.conv, self.block.forward(x, numerics), numerics)
    }
}

/// Context at three resolutions, two heads per level: `j = 0` becomes the GRU's initial hidden
/// state (after tanh), `j = 1` its context input (after ReLU).
///
/// All five trunk layers and all three levels of heads are built whatever the number of GRU
/// levels, as in the reference (its checkpoints hold them).
///
/// # Shapes
/// - input `[N, 3, H, W]`, level `l` outputs `[N, dims[2-l], H/(f·2^l), W/(f·2^l)]`
#[derive(Module, Debug)]
pub struct ContextEncoder {
    /// 7x7 stem convolution.
    pub conv1: Conv2d,
    /// Norm of the stem.
    pub norm1: Norm,
    /// `trunk[0]` channels (64).
    pub layer1: Vec<ResidualBlock>,
    /// `trunk[1]` channels (96).
    pub layer2: Vec<ResidualBlock>,
    /// `trunk[2]` channels (128), resolution 1/f.
    pub layer3: Vec<ResidualBlock>,
    /// `trunk[2]` channels, 1/(2f).
    pub layer4: Vec<ResidualBlock>,
    /// `trunk[2]` channels, 1/(4f).
    pub layer5: Vec<ResidualBlock>,
    /// Heads at 1/f.
    pub outputs08: Vec<ContextHead>,
    /// Heads at 1/(2f).
    pub outputs16: Vec<ContextHead>,
    /// Heads at 1/(4f): a single convolution each.
    pub outputs32: Vec<Conv2d>,
    /// The monocular features' block added before the 1/f heads (DEFOM-Stereo's `conv08`).
    pub conv08: Option<DepthFeatureBlock>,
    /// The same before the 1/(2f) heads (`conv16`).
    pub conv16: Option<DepthFeatureBlock>,
    /// The same before the 1/(4f) heads (`conv32`).
    pub conv32: Option<DepthFeatureBlock>,
}

impl ContextEncoder {
    /// `dims` are the reference's `hidden_dims` (`[1/16, 1/8, 1/4]` order), used for both the
    /// hidden and the context heads (`context_dims = hidden_dims`); `trunk` the widths of
    /// layer1..3 (`[64, 96, 128]` in the reference; layer4/5 keep the last); with
    /// `depth_channels`, it adds monocular features of that width before each level's heads
    /// ([`DepthFeatureBlock`]).
    pub fn new(
        dims: [usize; 3],
        trunk: [usize; 3],
        norm: NormKind,
        n_downsample: usize,
        depth_channels: Option<usize>,
        device: &Device,
    ) -> Self {
        let [s1, s2, s3] = trunk_strides(n_downsample);
        let [c1, c2, c3] = trunk;
        Self {
            conv1: conv2d([3, c1], 7, s1, 3, ConvInit::KaimingFanOut, device),
            norm1: norm.init(c1, device),
            layer1: make_layer(c1, c1, norm, 1, device),
            layer2: make_layer(c1, c2, norm, s2, device),
            layer3: make_layer(c2, c3, norm, s3, device),
            layer4: make_layer(c3, c3, norm, 2, device),
            layer5: make_layer(c3, c3, norm, 2, device),
            outputs08: (0..2).map(|_| ContextHead::new(c3, dims[2], norm, device)).collect(),
            outputs16: (0..2).map(|_| ContextHead::new(c3, dims[1], norm, device)).collect(),
            outputs32: (0..2).map(|_| conv2d([c3, dims[0]], 3, 1, 1, ConvInit::KaimingFanOut, device)).collect(),
            conv08: depth_channels.map(|d| DepthFeatureBlock::new(d, c3, norm, device)),
            conv16: depth_channels.map(|d| DepthFeatureBlock::new(d, c3, norm, device)),
            conv32: depth_channels.map(|d| DepthFeatureBlock::new(d, c3, norm, device)),
        }
    }

    /// The trunk output at 1/f (`[N, trunk[2], H/f, W/f]`), its convolutions with the rounding
    /// `numerics` allows in training.
    pub fn trunk(&self, image: Tensor<4>, numerics: Numerics) -> Tensor<4> {
        let x = self.norm1.conv_forward_relu(&self.conv1, image, true, numerics);
        let x = forward_layer(&self.layer1, x, numerics);
        let x = forward_layer(&self.layer2, x, numerics);
        forward_layer(&self.layer3, x, numerics)
    }

    /// Whether its norms are fixed per-channel maps (frozen batch norms, or none) rather than
    /// norms that divide by the activations' statistics.
    pub fn norms_are_fixed(&self) -> bool {
        matches!(self.norm1, Norm::Batch(_) | Norm::None(_))
    }

    /// The numerics its layers allow: [`Numerics::Tolerant`] where its norms are fixed
    /// ([`Self::norms_are_fixed`]: no norm of this encoder, and none after it, magnifies a change
    /// of rounding), else [`Numerics::Sensitive`]. For the whole forward (`context`), or for the
    /// heads alone where the trunk also feeds the shared backbone's feature head, whose instance
    /// norm would magnify it.
    pub fn numerics(&self) -> Numerics {
        if self.norms_are_fixed() { Numerics::Tolerant } else { Numerics::Sensitive }
    }

    /// The heads of `levels` levels from a trunk output, their convolutions with the rounding
    /// `numerics` allows in training. With `depth` (the monocular context features, finest
    /// first) and this encoder's [`DepthFeatureBlock`]s, each level's heads read the level's
    /// trunk output plus its block of the level's features; the coarser trunk layers read the
    /// trunk output alone, as in DEFOM-Stereo.
    pub fn heads(
        &self,
        trunk: Tensor<4>,
        levels: usize,
        numerics: Numerics,
        depth: Option<&[Tensor<4>]>,
    ) -> ContextFeatures {
        let with_depth = |block: &Option<DepthFeatureBlock>, x: Tensor<4>, level: usize| match (block, depth) {
            (Some(block), Some(depth)) => x + block.forward(depth[level].clone(), numerics),
            _ => x,
        };
        let pair = |heads: &[ContextHead], x: &Tensor<4>| {
            [heads[0].forward(x.clone(), numerics), heads[1].forward(x.clone(), numerics)]
        };
        let mut out = vec![pair(&self.outputs08, &with_depth(&self.conv08, trunk.clone(), 0))];
        if levels >= 2 {
            let y = forward_layer(&self.layer4, trunk, numerics);
            out.push(pair(&self.outputs16, &with_depth(&self.conv16, y.clone(), 1)));
            if levels >= 3 {
                let z = with_depth(&self.conv32, forward_layer(&self.layer5, y, numerics), 2);
                let [hidden, context] = [&self.outputs32[0], &self.outputs32[1]];
                out.push([conv2d_forward(hidden, z.clone(), numerics), conv2d_forward(context, z, numerics)]);
            }
        }
        ContextFeatures { levels: out }
    }

    /// The context of `levels` levels of `image`, with the monocular context features `depth`
    /// where the encoder adds them ([`Self::heads`]).
    pub fn context_with_depth(&self, image: Tensor<4>, levels: usize, depth: Option<&[Tensor<4>]>) -> ContextFeatures {
        let numerics = self.numerics();
        self.heads(self.trunk(image, numerics), levels, numerics, depth)
    }

    /// The context of `levels` levels of `image` (`[N, 3, H, W]`, normalised to -1..1).
    ///
    /// With fixed norms the training forward takes Winograd in every layer that suits it
    /// ([`Self::numerics`]): no norm of this encoder, and none after it, magnifies the change of
    /// rounding. With instance or group norms it keeps the plain products, as the feature
    /// encoder does.
    pub fn context(&self, image: Tensor<4>, levels: usize) -> ContextFeatures {
        self.context_with_depth(image, levels, None)
    }
}
