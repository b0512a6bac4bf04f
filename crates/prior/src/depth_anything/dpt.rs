//! The DPT head of Depth Anything V2 (`depth_head.*` in the checkpoints).
//!
//! Four token maps from the encoder are reassembled into a 4-level pyramid (1x1 `projects`, then
//! `resize_layers`: transposed conv 4x, transposed conv 2x, identity, 3x3 conv stride 2), brought
//! to `features` channels by the bias-free 3x3 `layerN_rn` convs, and fused coarse-to-fine by
//! four `FeatureFusionBlock`s (residual conv units, bilinear upsampling with
//! `align_corners=True`, a 1x1 `out_conv`). Two output convs and a final ReLU give one channel of
//! relative inverse depth at the input resolution.
//!
//! Field names follow the checkpoint keys except where PyTorch's are not Rust names; the loader
//! ([`super::checkpoint`]) maps `resize_layers.{0,1,3}`, `resConfUnit{1,2}` and
//! `output_conv2.{0,2}` onto them.

use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};
use dgstereo_kernels::resize_bilinear;
use dgstereo_kernels::{Numerics, conv2d_forward, conv2d_relu_forward};

use super::dinov2::{IntermediateLayer, PATCH_SIZE};

/// Channels of the hidden layer of `output_conv2` (`head_features_2` upstream).
const OUTPUT_HIDDEN: usize = 32;

pub(crate) fn conv(cin: usize, cout: usize, kernel: usize, stride: usize, bias: bool, device: &Device) -> Conv2d {
    let pad = kernel / 2;
    Conv2dConfig::new([cin, cout], [kernel, kernel])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_bias(bias)
        .init(device)
}

pub(crate) fn conv_transpose(channels: usize, factor: usize, device: &Device) -> ConvTranspose2d {
    ConvTranspose2dConfig::new([channels, channels], [factor, factor]).with_stride([factor, factor]).init(device)
}

/// `x + conv2(relu(conv1(relu(x))))` (no batch norm: Depth Anything V2 has `use_bn=False`).
#[derive(Module, Debug)]
pub struct ResidualConvUnit {
    /// First 3x3 conv.
    pub conv1: Conv2d,
    /// Second 3x3 conv.
    pub conv2: Conv2d,
}

impl ResidualConvUnit {
    fn new(features: usize, device: &Device) -> Self {
        Self {
            conv1: conv(features, features, 3, 1, true, device),
            conv2: conv(features, features, 3, 1, true, device),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = conv2d_forward(
            &self.conv2,
            conv2d_relu_forward(&self.conv1, relu(x.clone()), Numerics::Sensitive),
            Numerics::Sensitive,
        );
        y + x
    }
}

/// Fuses a coarser path with a skip connection, then upsamples.
#[derive(Module, Debug)]
pub struct FeatureFusionBlock {
    /// 1x1 conv after the upsampling.
    pub out_conv: Conv2d,
    /// Unit applied to the skip connection (`resConfUnit1`).
    pub res_conf_unit1: ResidualConvUnit,
    /// Unit applied to the sum (`resConfUnit2`).
    pub res_conf_unit2: ResidualConvUnit,
}

impl FeatureFusionBlock {
    pub(crate) fn new(features: usize, device: &Device) -> Self {
        Self {
            out_conv: conv(features, features, 1, 1, true, device),
            res_conf_unit1: ResidualConvUnit::new(features, device),
            res_conf_unit2: ResidualConvUnit::new(features, device),
        }
    }

    /// `out_conv(resize(rcu2(path + rcu1(skip))))`, resized (bilinear, align corners) to `size`:
    /// twice the input's in Depth Anything V2's last block, the input's own (no resize) in
    /// DEFOM-Stereo's modified blocks.
    ///
    /// # Shapes
    /// - `path`, `skip`: `[B, F, h, w]` -> `[B, F, size]`
    pub(crate) fn forward(&self, path: Tensor<4>, skip: Option<Tensor<4>>, size: [usize; 2]) -> Tensor<4> {
        let mut x = path;
        if let Some(skip) = skip {
            x = x + self.res_conf_unit1.forward(skip);
        }
        let x = resize_bilinear(self.res_conf_unit2.forward(x), size, true);
        conv2d_forward(&self.out_conv, x, Numerics::Sensitive)
    }
}

/// The `scratch` part of the head: channel adapters, fusion blocks and output convs.
#[derive(Module, Debug)]
pub struct Scratch {
    /// 3x3 conv, no bias, level 1 (1/14·4).
    pub layer1_rn: Conv2d,
    /// Level 2.
    pub layer2_rn: Conv2d,
    /// Level 3.
    pub layer3_rn: Conv2d,
    /// Level 4.
    pub layer4_rn: Conv2d,
    /// Finest fusion block.
    pub refinenet1: FeatureFusionBlock,
    /// Fusion block 2.
    pub refinenet2: FeatureFusionBlock,
    /// Fusion block 3.
    pub refinenet3: FeatureFusionBlock,
    /// Coarsest fusion block (no skip input).
    pub refinenet4: FeatureFusionBlock,
    /// 3x3 conv `F -> F/2`.
    pub output_conv1: Conv2d,
    /// 3x3 conv `F/2 -> 32` (`output_conv2.0`), followed by ReLU.
    pub output_conv2_hidden: Conv2d,
    /// 1x1 conv `32 -> 1` (`output_conv2.2`), followed by ReLU.
    pub output_conv2_out: Conv2d,
}

/// The DPT head.
#[derive(Module, Debug)]
pub struct DptHead {
    /// 1x1 convs from the token width to each level's channels.
    pub projects: Vec<Conv2d>,
    /// Level 1 resize (`resize_layers.0`): transposed conv, 4x.
    pub upsample_4x: ConvTranspose2d,
    /// Level 2 resize (`resize_layers.1`): transposed conv, 2x.
    pub upsample_2x: ConvTranspose2d,
    /// Level 4 resize (`resize_layers.3`): 3x3 conv, stride 2. Level 3 is the identity.
    pub downsample_2x: Conv2d,
    /// Fusion and output.
    pub scratch: Scratch,
}

impl DptHead {
    /// A randomly initialised head reading tokens of width `in_channels`.
    pub fn new(in_channels: usize, features: usize, out_channels: [usize; 4], device: &Device) -> Self {
        let fusion = || FeatureFusionBlock::new(features, device);
        Self {
            projects: out_channels.iter().map(|&c| conv(in_channels, c, 1, 1, true, device)).collect(),
            upsample_4x: conv_transpose(out_channels[0], 4, device),
            upsample_2x: conv_transpose(out_channels[1], 2, device),
            downsample_2x: conv(out_channels[3], out_channels[3], 3, 2, true, device),
            scratch: Scratch {
                layer1_rn: conv(out_channels[0], features, 3, 1, false, device),
                layer2_rn: conv(out_channels[1], features, 3, 1, false, device),
                layer3_rn: conv(out_channels[2], features, 3, 1, false, device),
                layer4_rn: conv(out_channels[3], features, 3, 1, false, device),
                refinenet1: fusion(),
                refinenet2: fusion(),
                refinenet3: fusion(),
                refinenet4: fusion(),
                output_conv1: conv(features, features / 2, 3, 1, true, device),
                output_conv2_hidden: conv(features / 2, OUTPUT_HIDDEN, 3, 1, true, device),
                output_conv2_out: conv(OUTPUT_HIDDEN, 1, 1, 1, true, device),
            },
        }
    }

    /// Depth from four intermediate encoder layers on a `grid = [h, w]` patch grid.
    ///
    /// # Shapes
    /// - `layers[i].tokens`: `[B, h·w, C]`
    /// - output: `[B, 1, 14h, 14w]`, non-negative
    pub fn forward(&self, layers: &[IntermediateLayer], grid: [usize; 2]) -> Tensor<4> {
        let [h, w] = grid;
        let path = self.fused(layers, grid, None, |[fh, fw]| [2 * fh, 2 * fw]);
        self.output(path, [h * PATCH_SIZE, w * PATCH_SIZE])
    }

    /// DEFOM-Stereo's `DPTHead`: the first `batch` images of the layers only (the left views of
    /// a stacked pair), its modified last fusion block that keeps the finest level's size, and the
    /// output convolutions' resize to `out_size` (the stereo network's update grid) instead of
    /// the input's size.
    ///
    /// # Shapes
    /// - `layers[i].tokens`: `[2·batch, h·w, C]`; output: `[batch, 1, out_size]`, non-negative
    pub fn inverse_depth_at(
        &self,
        layers: &[IntermediateLayer],
        grid: [usize; 2],
        batch: usize,
        out_size: [usize; 2],
    ) -> Tensor<4> {
        let path = self.fused(layers, grid, Some(batch), |size| size);
        self.output(path, out_size)
    }

    /// The fused finest level: reassembly, the channel adapters and the four fusion blocks, the
    /// last resized to `finest(size of level 1)`; of the first `batch` images when given.
    fn fused(
        &self,
        layers: &[IntermediateLayer],
        grid: [usize; 2],
        batch: Option<usize>,
        finest: impl Fn([usize; 2]) -> [usize; 2],
    ) -> Tensor<4> {
        let resize = [&self.upsample_4x, &self.upsample_2x];
        let [l1, l2, l3, l4] = reassemble(&self.projects, resize, &self.downsample_2x, layers, grid, batch);
        let s = &self.scratch;
        let [l1, l2, l3, l4] = adapt([&s.layer1_rn, &s.layer2_rn, &s.layer3_rn, &s.layer4_rn], [l1, l2, l3, l4]);
        let path = s.refinenet4.forward(l4, None, spatial(&l3));
        let path = s.refinenet3.forward(path, Some(l3), spatial(&l2));
        let path = s.refinenet2.forward(path, Some(l2), spatial(&l1));
        let size = finest(spatial(&l1));
        s.refinenet1.forward(path, Some(l1), size)
    }

    /// `output_conv1`, the resize to `size` (bilinear, align corners), `output_conv2` with its
    /// two ReLUs.
    fn output(&self, path: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
        let s = &self.scratch;
        let out = conv2d_forward(&s.output_conv1, path, Numerics::Sensitive);
        let out = resize_bilinear(out, size, true);
        let out = conv2d_relu_forward(&s.output_conv2_hidden, out, Numerics::Sensitive);
        conv2d_relu_forward(&s.output_conv2_out, out, Numerics::Sensitive)
    }
}

/// The spatial size `[h, w]` of `[B, C, h, w]`.
pub(crate) fn spatial(t: &Tensor<4>) -> [usize; 2] {
    let [_, _, h, w] = t.dims();
    [h, w]
}

/// The DPT reassembly: each layer's patch tokens (of the first `batch` images when given) as a
/// map on the `grid`, its 1x1 projection, then the level's resize (transposed conv 4x and 2x,
/// identity, 3x3 conv stride 2).
///
/// # Shapes
/// - `layers[i].tokens`: `[B, h·w, C]` -> level `i`: `[B', out_channels[i], 4h, 4w]`, `[.., 2h, 2w]`,
///   `[.., h, w]`, `[.., ceil(h/2), ceil(w/2)]`
pub(crate) fn reassemble(
    projects: &[Conv2d],
    [upsample_4x, upsample_2x]: [&ConvTranspose2d; 2],
    downsample_2x: &Conv2d,
    layers: &[IntermediateLayer],
    grid: [usize; 2],
    batch: Option<usize>,
) -> [Tensor<4>; 4] {
    assert_eq!(layers.len(), 4, "the DPT head takes four encoder layers");
    let [h, w] = grid;
    let maps: Vec<Tensor<4>> = layers
        .iter()
        .zip(projects)
        .map(|(layer, project)| {
            let tokens = match batch {
                Some(n) => layer.tokens.clone().narrow(0, 0, n),
                None => layer.tokens.clone(),
            };
            let [b, n, c] = tokens.dims();
            assert_eq!(n, h * w, "token count {n} does not match the {h}x{w} patch grid");
            conv2d_forward(project, tokens.swap_dims(1, 2).reshape([b, c, h, w]), Numerics::Sensitive)
        })
        .collect();
    let [l1, l2, l3, l4]: [Tensor<4>; 4] = maps.try_into().expect("four maps");
    [upsample_4x.forward(l1), upsample_2x.forward(l2), l3, conv2d_forward(downsample_2x, l4, Numerics::Sensitive)]
}

/// The bias-free 3x3 channel adapters `layerN_rn` on the four reassembled levels.
pub(crate) fn adapt(convs: [&Conv2d; 4], levels: [Tensor<4>; 4]) -> [Tensor<4>; 4] {
    let mut out = levels.into_iter().zip(convs).map(|(l, c)| conv2d_forward(c, l, Numerics::Sensitive));
    std::array::from_fn(|_| out.next().expect("four levels"))
}
