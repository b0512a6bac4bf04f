//! The convolution's algorithms, and the fused ConvGRU step's, with every threshold that picks
//! one.
//!
//! Design decision: the host convolution has four algorithms (Winograd F(4x4, 3x3) or
//! F(2x2, 3x3), in bands or in cache-resident blocks; the few-output kernel; im2col tiles), the
//! training node chooses among them for its forward and its two gradients, and the ConvGRU step
//! shares Winograd's transforms between its two convolutions. All of that is decided here, from
//! the shapes and the settings, so the kernels only carry out what they are given and a new
//! threshold has one place to go. The thresholds are where each algorithm starts to pay on this
//! workload (docs/performance.md has the measurements).

use burn::nn::conv::Conv2d;
use burn::tensor::Device;
use burn::tensor::ops::ConvOptions;

use super::calls::conv_on_gpu;
use super::product_forms::{few_outputs, gpu_conv_form, shared_columns_form};
use super::{Call, Numerics, Op, products_unit};
use crate::algorithm::{Bf16Unit, ConvAlgorithm, ConvTraining, GpuConvForm, GruAlgorithm, WinogradTile};
use crate::geometry::{conv_options, conv_output_size};
use crate::host::winograd::blocks_available;
use crate::settings::{Bf16Winograd, Settings};

/// Fewest input and output channels for which Winograd pays against im2col tiles.
const WINOGRAD_MIN_CHANNELS: usize = 32;

/// Fewest 2x2 output tiles (over the batch) for which Winograd pays: the weight transform and the
/// bands' fixed costs need enough tiles.
const WINOGRAD_MIN_TILES: usize = 64;

/// Fewest 4x4 tiles (over the batch) for F(4x4) rather than F(2x2): its weight transform is
/// 2.25x larger and its bands coarser.
pub(crate) const WINOGRAD_MIN_F4_TILES: usize = 128;

/// The largest `C·O` that F(4x4) runs in cache-resident blocks: they beat the bands on the
/// encoders' 64- to 128-channel layers and the heads' 128->256 first layers, and lose on the
/// GRUs' 384->128, where the `gemm` crate's products over hundreds of tiles per read of the
/// weights win.
const BLOCKS_MAX_CHANNEL_PRODUCT: usize = 128 * 256;

/// Fewest input channels for which training takes the node with our backward. The stems (3
/// input channels, a 7x7 kernel at stride 2, each followed by an instance or batch norm) keep
/// burn's: with ours the official training step's check fails on gradients of the feature
/// encoder, whose instance norms magnify a different summation order in the stem's output; and
/// they are a small share of a step.
pub(crate) const TRAINING_MIN_CHANNELS: usize = 16;

/// Fewest input channels for which the training forward takes Winograd under
/// [`Numerics::Sensitive`]: the ConvGRUs' gate and candidate convolutions (256 or 384 input
/// channels, most of an update iteration's products). The feature encoder's layers (at most 128
/// input channels) keep plain products, whose rounding its instance norms magnify. The weight
/// gradient takes Winograd wherever the layer suits it: a weight's gradient feeds no other
/// gradient, so its rounding is not magnified.
pub(crate) const TRAINING_WINOGRAD_MIN_CHANNELS: usize = 256;

/// The Winograd tile for a convolution of an `x_dims = [N, C, H, W]` input with a
/// `w_dims = [O, C, kh, kw]` weight, `None` where it does not pay: 3x3, stride 1, dilation 1,
/// groups 1, at least [`WINOGRAD_MIN_CHANNELS`] input and output channels and
/// [`WINOGRAD_MIN_TILES`] 2x2 output tiles; F(4x4) from [`WINOGRAD_MIN_F4_TILES`] 4x4 tiles.
pub(crate) fn winograd_tile(x_dims: [usize; 4], w_dims: [usize; 4], options: &ConvOptions<2>) -> Option<WinogradTile> {
    let [n, c, h, w] = x_dims;
    let [o, _, kh, kw] = w_dims;
    let [(ph, ph_end), (pw, pw_end)] = options.padding;
    let (out_h, out_w) = ((h + ph + ph_end).saturating_sub(2), (w + pw + pw_end).saturating_sub(2));
    let tiles = |m: usize| out_h.div_ceil(m) * out_w.div_ceil(m);
    let suits = [kh, kw] == [3, 3]
        && options.stride == [1, 1]
        && options.dilation == [1, 1]
        && options.groups == 1
        && c.min(o) >= WINOGRAD_MIN_CHANNELS
        && n * tiles(2) >= WINOGRAD_MIN_TILES;
    suits.then_some(if n * tiles(4) >= WINOGRAD_MIN_F4_TILES { WinogradTile::F4 } else { WinogradTile::F2 })
}

/// The host convolution's algorithm for one group: Winograd where `winograd` allows it, the
/// settings leave it on and the shape suits it ([`winograd_tile`]; F(4x4) in blocks where the
/// processor has AVX-512, the settings leave them on and `C·O` is at most
/// [`BLOCKS_MAX_CHANNEL_PRODUCT`]); else the few-output kernel where it suits ([`few_outputs`]);
/// else im2col tiles.
pub(crate) fn host_algorithm(
    x_dims: [usize; 4],
    w_dims: [usize; 4],
    options: &ConvOptions<2>,
    winograd: bool,
    settings: &Settings,
) -> ConvAlgorithm {
    let [_, c, _, _] = x_dims;
    let o = w_dims[0];
    match winograd_tile(x_dims, w_dims, options).filter(|_| winograd && settings.winograd) {
        Some(tile) => {
            let blocks = tile == WinogradTile::F4
                && settings.winograd_blocks
                && c * o <= BLOCKS_MAX_CHANNEL_PRODUCT
                && blocks_available();
            ConvAlgorithm::Winograd { tile, blocks }
        }
        None if few_outputs(options, o, c) => ConvAlgorithm::FewOutputs,
        None => ConvAlgorithm::Im2col,
    }
}

/// The inference algorithm of `algorithm`'s layer with its products in bf16 on `unit`: im2col
/// tiles take bf16 products; Winograd in bands takes them with the tile the settings'
/// `bf16-winograd` gives ([`bf16_tile`]; Winograd's transforms stay f32, only the products'
/// inputs are rounded) or keeps f32; F(4x4) in blocks (the layers with few channels) keeps its
/// f32 kernel unless `bf16-winograd=f2`; the few-output kernel, whose time goes to reading the
/// input rather than to its products, stays f32.
///
/// Measured on the 2-core AMD EPYC (Zen 4, AVX512-BF16, no AMX), CPU seconds of a 384x448 x 32
/// pass on a loaded machine (docs/performance.md): f32 9.7-9.8 s; bf16 with `f4` (blocks
/// kept f32) the least; `f2` 11.9-12.1 s (F(2x2) does 1.8x the products of F(4x4) and its
/// transforms more, which bf16's 1.9x product rate does not repay); `off` 9.8-9.9 s.
pub(crate) fn in_bf16(algorithm: ConvAlgorithm, unit: Bf16Unit, settings: &Settings) -> ConvAlgorithm {
    match algorithm {
        ConvAlgorithm::Winograd { blocks: true, .. } if settings.bf16_winograd != Bf16Winograd::F2 => algorithm,
        ConvAlgorithm::Winograd { tile, .. } | ConvAlgorithm::WinogradBf16 { tile, .. } => {
            match bf16_tile(tile, settings) {
                Some(tile) => ConvAlgorithm::WinogradBf16 { tile, unit },
                None => algorithm,
            }
        }
        ConvAlgorithm::Im2col | ConvAlgorithm::Im2colBf16(_) => ConvAlgorithm::Im2colBf16(unit),
        ConvAlgorithm::FewOutputs => ConvAlgorithm::FewOutputs,
    }
}

/// The Winograd tile of a layer that takes `tile` in f32, with bf16 products: `None` (f32
/// products) under `bf16-winograd=off`, F(2x2) under `f2`, `tile` under `f4` (the default).
/// With bf16 inputs F(4x4)'s transforms err by about 6e-3 of the largest sum of absolute
/// products at the GRU's 384 channels (5 % at 4 channels), F(2x2) by 4e-4, as a direct product;
/// on Cones with the bundled default every choice keeps the EPE within 0.002 px of f32's.
fn bf16_tile(tile: WinogradTile, settings: &Settings) -> Option<WinogradTile> {
    match settings.bf16_winograd {
        Bf16Winograd::Off => None,
        Bf16Winograd::F2 => Some(WinogradTile::F2),
        Bf16Winograd::F4 => Some(tile),
    }
}

/// One convolution: the input's and the weight's dimensions, the options and the numerics its
/// caller allows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConvCall<'a> {
    /// `[N, C, H, W]`.
    pub(crate) x_dims: [usize; 4],
    /// `[O, C / groups, kh, kw]`.
    pub(crate) w_dims: [usize; 4],
    /// Stride, padding, dilation, groups.
    pub(crate) options: &'a ConvOptions<2>,
    /// What may follow the layer.
    pub(crate) numerics: Numerics,
}

impl Call for ConvCall<'_> {
    type Inference = ConvAlgorithm;
    type Training = ConvTraining;
    type Gpu = GpuConvForm;

    fn op(&self) -> Op {
        Op::Conv
    }

    /// The host algorithm of one group ([`host_algorithm`]), with bf16 products ([`in_bf16`])
    /// where the calling thread asks for them and the processor has a unit.
    fn inference(&self, settings: &Settings) -> Option<ConvAlgorithm> {
        let algorithm = host_algorithm(self.x_dims, self.w_dims, self.options, true, settings);
        let algorithm = match products_unit(settings) {
            Some(unit) => in_bf16(algorithm, unit, settings),
            None => algorithm,
        };
        (self.options.groups == 1).then_some(algorithm)
    }

    /// From [`TRAINING_MIN_CHANNELS`] input channels, one group; the forward by Winograd only
    /// from [`TRAINING_WINOGRAD_MIN_CHANNELS`] input channels unless the numerics are
    /// [`Numerics::Tolerant`]; the input gradient by the host convolution for stride 1, dilation
    /// 1 and a padding below the kernel; the weight gradient by Winograd where the layer suits it.
    fn training(&self, settings: &Settings) -> Option<ConvTraining> {
        (self.options.groups == 1 && self.x_dims[1] >= TRAINING_MIN_CHANNELS)
            .then(|| training_algorithms(self.x_dims, self.w_dims, self.options, self.numerics, settings))
    }

    /// The GPU's product and its form ([`gpu_conv_form`]).
    fn gpu(&self, settings: &Settings, _: &Device) -> Option<GpuConvForm> {
        gpu_conv_form(self.x_dims, self.w_dims, self.options, settings)
    }
}

/// The training node's algorithms for a convolution of one group (see [`ConvCall`]'s `training`).
pub(crate) fn training_algorithms(
    x_dims: [usize; 4],
    w_dims: [usize; 4],
    options: &ConvOptions<2>,
    numerics: Numerics,
    settings: &Settings,
) -> ConvTraining {
    let [n, c, h, w] = x_dims;
    let [o, _, kh, kw] = w_dims;
    let winograd = c >= TRAINING_WINOGRAD_MIN_CHANNELS || numerics == Numerics::Tolerant;
    let forward = host_algorithm(x_dims, w_dims, options, winograd, settings);
    let [(pt, pb), (pl, pr)] = options.padding;
    let plain = options.stride == [1, 1] && options.dilation == [1, 1];
    let input_grad = (plain && pt.max(pb) < kh && pl.max(pr) < kw).then(|| {
        let [out_h, out_w] = conv_output_size("conv2d", [h, w], [kh, kw], options);
        let padding = [(kh - 1 - pt, kh - 1 - pb), (kw - 1 - pl, kw - 1 - pr)];
        let transposed = ConvOptions::new_with_padding([1, 1], padding, [1, 1], 1);
        host_algorithm([n, o, out_h, out_w], [c, o, kh, kw], &transposed, true, settings)
    });
    let weight_grad = winograd_tile(x_dims, w_dims, options).filter(|_| settings.winograd);
    ConvTraining { forward, input_grad, weight_grad }
}

/// One ConvGRU step: its three convolutions, the state's dimensions and the inputs' channels.
#[derive(Debug, Clone)]
pub(crate) struct GruStepCall {
    /// The options of `convz`, `convr` and `convq`, where the host kernel takes them.
    options: [Option<ConvOptions<2>>; 3],
    /// The kernels of `convz` and `convq`.
    kernels: [[usize; 2]; 2],
    /// The tensor-op step's gate options ([`GruStepCall::gate_options`]).
    gates: ConvOptions<2>,
    /// `[N, C, H, W]` of the state.
    h_dims: [usize; 4],
    /// The inputs' channels together.
    input_channels: usize,
}

impl GruStepCall {
    /// The step of `convs` (`convz`, `convr`, `convq`) on a state of `h_dims` with inputs of
    /// `input_channels` channels together.
    pub(crate) fn new([convz, convr, convq]: [&Conv2d; 3], h_dims: [usize; 4], input_channels: usize) -> Self {
        let kernel = |conv: &Conv2d| {
            let [_, _, kh, kw] = conv.weight.dims();
            [kh, kw]
        };
        Self {
            options: [conv_options(convz), conv_options(convr), conv_options(convq)],
            kernels: [kernel(convz), kernel(convq)],
            gates: Self::gate_options(convz),
            h_dims,
            input_channels,
        }
    }

    /// The gates' options: `convz`'s stride, dilation and groups, padded to keep the size.
    pub(crate) fn gate_options(convz: &Conv2d) -> ConvOptions<2> {
        let [_, _, kh, kw] = convz.weight.dims();
        ConvOptions::new(convz.stride, [kh / 2, kw / 2], convz.dilation, convz.groups)
    }
}

impl Call for GruStepCall {
    type Inference = GruAlgorithm;
    type Training = ();
    type Gpu = GpuConvForm;

    fn op(&self) -> Op {
        Op::GruStep
    }

    /// The fused step where the host convolution takes all three convolutions and `convr` has
    /// `convz`'s options; its convolutions share Winograd's transforms where both take it with
    /// equal options and 3x3 kernels.
    fn inference(&self, settings: &Settings) -> Option<GruAlgorithm> {
        let [Some(zr), Some(r), Some(q)] = &self.options else { return None };
        if r != zr {
            return None;
        }
        let [n, c, h, w] = self.h_dims;
        let channels = c + self.input_channels;
        let dims = [n, channels, h, w];
        let [[kh, kw], [qh, qw]] = self.kernels;
        let (gates_w, candidate_w) = ([2 * c, channels, kh, kw], [c, channels, qh, qw]);
        let shared = (zr == q && [kh, kw, qh, qw] == [3; 4] && settings.winograd)
            .then(|| winograd_tile(dims, gates_w, zr).zip(winograd_tile(dims, candidate_w, q)))
            .flatten();
        let unit = products_unit(settings);
        let products = |algorithm| unit.map_or(algorithm, |unit| in_bf16(algorithm, unit, settings));
        Some(match (shared, unit) {
            (Some((tile, _)), None) => GruAlgorithm::Shared(tile),
            (Some((tile, _)), Some(unit)) => match bf16_tile(tile, settings) {
                Some(tile) => GruAlgorithm::SharedBf16(tile, unit),
                None => GruAlgorithm::Shared(tile),
            },
            (None, _) => GruAlgorithm::Separate {
                gates: products(host_algorithm(dims, gates_w, zr, true, settings)),
                candidate: products(host_algorithm(dims, candidate_w, q, true, settings)),
            },
        })
    }

    /// The tensor-op step, whose gates and blend are nodes with our backward.
    fn training(&self, _: &Settings) -> Option<()> {
        Some(())
    }

    /// The shared columns where the convolutions take the GPU's product
    /// ([`shared_columns_form`]).
    fn gpu(&self, settings: &Settings, device: &Device) -> Option<GpuConvForm> {
        let candidate_fits = self.options[2].as_ref() == Some(&self.gates);
        shared_columns_form(&self.gates, self.kernels[0], settings).filter(|_| conv_on_gpu(device) && candidate_fits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(stride: usize, padding: usize, dilation: usize) -> ConvOptions<2> {
        ConvOptions::new([stride; 2], [padding; 2], [dilation; 2], 1)
    }

    /// The host algorithm of representative layers of the default model at 384x448 (the choices
    /// the kernels were tuned with), with the default settings.
    #[test]
    fn inference_algorithms_of_representative_layers() {
        let s = Settings::default();
        let blocks = blocks_available();
        let winograd = |tile, blocks| ConvAlgorithm::Winograd { tile, blocks };
        let f4_blocks = winograd(WinogradTile::F4, blocks);
        type Row = (&'static str, [usize; 4], [usize; 4], ConvOptions<2>, ConvAlgorithm);
        let table: [Row; 12] = [
            ("stem 7x7/2", [1, 3, 384, 448], [64, 3, 7, 7], options(2, 3, 1), ConvAlgorithm::Im2col),
            ("layer1 3x3 64", [1, 64, 192, 224], [64, 64, 3, 3], options(1, 1, 1), f4_blocks),
            ("layer2 3x3/2", [1, 64, 192, 224], [96, 64, 3, 3], options(2, 1, 1), ConvAlgorithm::Im2col),
            ("layer3 3x3 128", [1, 128, 48, 56], [128, 128, 3, 3], options(1, 1, 1), f4_blocks),
            (
                "GRU 1/4 384->256",
                [1, 384, 96, 112],
                [256, 384, 3, 3],
                options(1, 1, 1),
                winograd(WinogradTile::F4, false),
            ),
            (
                "GRU 1/16 small grid",
                [1, 384, 24, 28],
                [256, 384, 3, 3],
                options(1, 1, 1),
                winograd(WinogradTile::F2, false),
            ),
            ("flow head 256->2", [1, 256, 96, 112], [2, 256, 3, 3], options(1, 1, 1), ConvAlgorithm::FewOutputs),
            ("motion 1x1 36->64", [1, 36, 96, 112], [64, 36, 1, 1], options(1, 0, 1), ConvAlgorithm::Im2col),
            ("few tiles", [1, 32, 16, 14], [32, 32, 3, 3], options(1, 1, 1), ConvAlgorithm::Im2col),
            ("few channels", [1, 16, 96, 112], [16, 16, 3, 3], options(1, 1, 1), ConvAlgorithm::Im2col),
            ("dilated", [1, 64, 96, 112], [64, 64, 3, 3], options(1, 2, 2), ConvAlgorithm::Im2col),
            ("few outputs, few inputs", [1, 16, 96, 112], [2, 16, 3, 3], options(1, 1, 1), ConvAlgorithm::Im2col),
        ];
        for (name, x, w, options, want) in table {
            let call = ConvCall { x_dims: x, w_dims: w, options: &options, numerics: Numerics::Sensitive };
            assert_eq!(call.inference(&s), Some(want), "{name}");
        }
        let grouped = ConvOptions::new([1, 1], [1, 1], [1, 1], 2);
        let call = ConvCall {
            x_dims: [1, 64, 96, 112],
            w_dims: [64, 32, 3, 3],
            options: &grouped,
            numerics: Numerics::Sensitive,
        };
        assert_eq!(call.inference(&s), None, "groups take burn's convolution");
        let off: Settings = "no-winograd".parse().expect("a setting");
        let call = ConvCall {
            x_dims: [1, 64, 96, 112],
            w_dims: [64, 64, 3, 3],
            options: &options(1, 1, 1),
            numerics: Numerics::Sensitive,
        };
        assert_eq!(call.inference(&off), Some(ConvAlgorithm::Im2col));
        let bands: Settings = "no-winograd-blocks".parse().expect("a setting");
        assert_eq!(call.inference(&bands), Some(winograd(WinogradTile::F4, false)));
    }

    /// Winograd's tile: F(4x4) from enough 4x4 tiles, F(2x2) below, none for other kernels,
    /// strides, dilations, groups, too few channels or tiles.
    #[test]
    fn winograd_takes_3x3_stride_1_with_many_channels() {
        let tile = winograd_tile;
        assert_eq!(tile([1, 384, 96, 112], [128, 384, 3, 3], &options(1, 1, 1)), Some(WinogradTile::F4));
        assert_eq!(tile([1, 32, 16, 16], [32, 32, 3, 3], &options(1, 1, 1)), Some(WinogradTile::F2), "64 tiles");
        assert_eq!(tile([4, 32, 8, 8], [32, 32, 3, 3], &options(1, 1, 1)), Some(WinogradTile::F2), "over the batch");
        let side = 4 * (WINOGRAD_MIN_F4_TILES as f64).sqrt().ceil() as usize;
        assert_eq!(tile([1, 64, side, side], [64, 64, 3, 3], &options(1, 1, 1)), Some(WinogradTile::F4));
        assert_eq!(tile([1, 64, side - 8, side], [64, 64, 3, 3], &options(1, 1, 1)), Some(WinogradTile::F2));
        let none = [
            ([1, 32, 16, 14], [32, 32, 3, 3], options(1, 1, 1)), // 56 tiles
            ([1, 32, 18, 16], [32, 32, 3, 3], options(1, 0, 1)), // 56 tiles unpadded
            ([1, 384, 96, 112], [128, 384, 3, 3], options(2, 1, 1)),
            ([1, 384, 96, 112], [128, 384, 3, 3], options(1, 2, 2)),
            ([1, 384, 96, 112], [128, 384, 1, 1], options(1, 0, 1)),
            ([1, 64, 96, 112], [64, 64, 7, 7], options(1, 3, 1)),
            ([1, 3, 96, 112], [64, 3, 3, 3], options(1, 1, 1)),
            ([1, 128, 96, 112], [2, 128, 3, 3], options(1, 1, 1)),
            ([1, 16, 96, 112], [16, 16, 3, 3], options(1, 1, 1)),
            ([1, 64, 1, 1], [64, 64, 3, 3], options(1, 1, 1)),
            ([1, 64, 96, 112], [64, 32, 3, 3], ConvOptions::new([1, 1], [1, 1], [1, 1], 2)),
        ];
        for (x, w, options) in none {
            assert_eq!(tile(x, w, &options), None, "{x:?} {w:?} {options:?}");
        }
    }

    /// The training node's choices: the stems keep burn's; below 256 input channels the forward
    /// keeps plain products unless the numerics are tolerant; the gradients by the host kernels.
    #[test]
    fn training_algorithms_follow_the_numerics() {
        let s = Settings::default();
        let same = options(1, 1, 1);
        let call = |x, w, options: &ConvOptions<2>, numerics| {
            ConvCall { x_dims: x, w_dims: w, options, numerics }.training(&s)
        };
        assert_eq!(call([1, 3, 64, 64], [64, 3, 7, 7], &options(2, 3, 1), Numerics::Tolerant), None, "the stem");
        let layer = call([1, 64, 48, 56], [64, 64, 3, 3], &same, Numerics::Sensitive).expect("a node");
        assert_eq!(layer.forward, ConvAlgorithm::Im2col);
        assert!(matches!(layer.input_grad, Some(ConvAlgorithm::Winograd { .. })));
        assert_eq!(layer.weight_grad, Some(WinogradTile::F4));
        let tolerant = call([1, 64, 48, 56], [64, 64, 3, 3], &same, Numerics::Tolerant).expect("a node");
        assert!(matches!(tolerant.forward, ConvAlgorithm::Winograd { tile: WinogradTile::F4, .. }));
        let gru = call([1, 384, 48, 56], [256, 384, 3, 3], &same, Numerics::Sensitive).expect("a node");
        assert!(matches!(gru.forward, ConvAlgorithm::Winograd { .. }), "the GRUs' width takes Winograd");
        let strided = call([1, 64, 48, 56], [96, 64, 3, 3], &options(2, 1, 1), Numerics::Tolerant).expect("a node");
        assert_eq!((strided.input_grad, strided.weight_grad), (None, None), "burn's input gradient");
    }

    /// The fused GRU step: both convolutions by Winograd sharing the inputs' transforms at the
    /// 1/4 grid of 384x448, each by im2col tiles on a grid too small for Winograd, none where a
    /// convolution has groups.
    #[test]
    fn gru_step_algorithms_of_representative_grids() {
        use burn::nn::PaddingConfig2d;
        use burn::nn::conv::Conv2dConfig;
        let device = Device::flex();
        let (hidden, input) = (128, 256);
        let conv = || {
            Conv2dConfig::new([hidden + input, hidden], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(&device)
        };
        let (z, r, q) = (conv(), conv(), conv());
        let s = Settings::default();
        let step = |h: usize, w: usize| GruStepCall::new([&z, &r, &q], [1, hidden, h, w], input).inference(&s);
        assert_eq!(step(96, 112), Some(GruAlgorithm::Shared(WinogradTile::F4)));
        assert_eq!(step(24, 28), Some(GruAlgorithm::Shared(WinogradTile::F2)));
        let im2col = GruAlgorithm::Separate { gates: ConvAlgorithm::Im2col, candidate: ConvAlgorithm::Im2col };
        assert_eq!(step(12, 14), Some(im2col));
        let off: Settings = "no-winograd".parse().expect("a setting");
        let call = GruStepCall::new([&z, &r, &q], [1, hidden, 96, 112], input);
        assert_eq!(call.inference(&off), Some(im2col));
        let grouped = Conv2dConfig::new([hidden + input, hidden], [3, 3]).with_groups(2).init(&device);
        assert_eq!(GruStepCall::new([&grouped, &r, &q], [1, hidden, 96, 112], input).inference(&s), None);
    }
}
