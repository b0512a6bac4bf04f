//! The operations whose products take bf16 in CPU inference ([`crate::ProductPrecision::Bf16`]),
//! each against burn's f32 operation with a bf16 tolerance: the convolution on every host
//! algorithm, the ConvGRU step (shared Winograd transforms and separate convolutions), the
//! correlation volume and the linear layer (the ViT's projections). Where the processor has no bf16 unit they compare f32 with f32 and say so.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::module::conv2d;
use burn::tensor::{Device, Distribution, Tensor};
use dgstereo_core::tensor::max_abs_diff;

use crate::algorithm::{ConvAlgorithm, GruAlgorithm};
use crate::dispatch::{Call, ConvCall, GruStepCall, Numerics, Path, Plan, ProductPrecision, with_path, with_products};
use crate::ops::conv::conv_options;
use crate::settings::settings;
use crate::{CorrelationPyramid, all_pairs, conv_gru_step, conv2d_forward};

/// The largest error of a bf16 product relative to the largest sum of absolute products: both
/// inputs rounded (2⁻⁹ each, so 2⁻⁸ a product) and Winograd's transforms, whose coefficients
/// (up to 8 and 5 in F(4x4)) grow the rounded terms before they cancel.
const BOUND: f32 = 2e-2;

/// Whether the processor has a bf16 unit; prints that the comparisons are f32 with f32 if not.
fn unit_present(test: &str) -> bool {
    let unit = crate::dispatch::bf16_unit();
    if unit.is_none() {
        eprintln!("{test}: no bf16 unit on this processor, so bf16 products run in f32; compared anyway");
    }
    unit.is_some()
}

/// `conv` of `x` with products in bf16 on the host path, and its error against burn's f32
/// convolution relative to the largest sum of absolute products.
fn conv_error(conv: &Conv2d, x: Tensor<4>) -> f32 {
    let got = with_path(Path::Host, || {
        with_products(ProductPrecision::Bf16, || conv2d_forward(conv, x.clone(), Numerics::Sensitive))
    });
    let (expected, magnitude) = with_path(Path::Stock, || {
        let options = conv_options(conv).expect("plain options");
        let b = conv.bias.as_ref().map(|b| b.val());
        let magnitude = conv2d(x.clone().abs(), conv.weight.val().abs(), b.clone().map(|b| b.abs()), options.clone());
        (conv2d(x, conv.weight.val(), b, options), magnitude)
    });
    max_abs_diff(expected, got) / magnitude.max().into_scalar::<f32>().max(1e-6)
}

/// Every host algorithm with bf16 products against burn's f32 convolution: Winograd F(4x4)
/// and F(2x2) in bands, im2col at stride 1 and 2, 1x1 and the 7x7 stem; F(4x4) in blocks and
/// the few-output kernel stay f32. Asserts the dispatch chose the bf16 forms where a unit exists.
#[test]
fn convolutions_with_bf16_products_meet_burns_f32() {
    let present = unit_present("convolutions");
    let device = Device::flex();
    let blocks = crate::host::winograd::blocks_available();
    // Name, kernel, stride, padding, [C, O], [H, W], whether the products take bf16.
    type Case = (&'static str, usize, usize, usize, [usize; 2], [usize; 2], bool);
    let cases: [Case; 8] = [
        ("winograd F(4x4) bands", 3, 1, 1, [192, 192], [48, 52], true),
        ("winograd F(4x4) blocks", 3, 1, 1, [64, 64], [48, 52], !blocks),
        ("winograd F(2x2)", 3, 1, 1, [48, 40], [16, 18], true),
        ("im2col 3x3, few channels", 3, 1, 1, [16, 24], [20, 22], true),
        ("im2col 3x3 stride 2", 3, 2, 1, [40, 48], [21, 30], true),
        ("im2col 1x1", 1, 1, 0, [36, 64], [18, 20], true),
        ("im2col 7x7 stem", 7, 2, 3, [3, 64], [40, 48], true),
        ("few outputs", 3, 1, 1, [64, 2], [20, 22], false),
    ];
    for (name, k, stride, pad, [c, o], [h, w], takes_bf16) in cases {
        let conv = Conv2dConfig::new([c, o], [k, k])
            .with_stride([stride, stride])
            .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
            .init(&device);
        let x = Tensor::<4>::random([1, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let options = conv_options(&conv).expect("plain options");
        let call =
            ConvCall { x_dims: x.dims(), w_dims: conv.weight.dims(), options: &options, numerics: Numerics::Sensitive };
        let algorithm = with_products(ProductPrecision::Bf16, || call.inference(settings())).expect("a host algorithm");
        let bf16 = matches!(algorithm, ConvAlgorithm::Im2colBf16(_) | ConvAlgorithm::WinogradBf16 { .. });
        assert_eq!(bf16, present && takes_bf16, "{name}: {algorithm:?}");
        let error = conv_error(&conv, x);
        eprintln!("{name}: {algorithm:?}, error {error:.2e} of the largest sum of |products|");
        assert!(error < BOUND, "{name}: {error}");
    }
}

/// The ConvGRU step with bf16 products against the tensor-op step in f32: on a grid that takes
/// the shared Winograd transforms and on one too small for Winograd.
#[test]
fn the_gru_step_with_bf16_products_meets_the_f32_step() {
    let present = unit_present("GRU step");
    let device = Device::flex();
    let (hidden, input) = (64, 96);
    let conv = || {
        Conv2dConfig::new([hidden + input, hidden], [3, 3])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(&device)
    };
    let (z, r, q) = (conv(), conv(), conv());
    for [h, w] in [[24, 28], [6, 7]] {
        let rand = |c: usize| Tensor::<4>::random([1, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let (state, zr_ctx, q_ctx, x) = (rand(hidden).tanh(), rand(2 * hidden), rand(hidden), rand(input));
        let step = || {
            conv_gru_step([&z, &r, &q], state.clone(), [&zr_ctx, &q_ctx], std::slice::from_ref(&x), Numerics::Tolerant)
        };
        let algorithm = with_products(ProductPrecision::Bf16, || {
            GruStepCall::new([&z, &r, &q], [1, hidden, h, w], input).inference(settings())
        });
        if present {
            let bf16 = matches!(
                algorithm,
                Some(GruAlgorithm::SharedBf16(..))
                    | Some(GruAlgorithm::Separate { gates: ConvAlgorithm::Im2colBf16(_), .. })
            );
            assert!(bf16, "{h}x{w}: {algorithm:?}");
        }
        let got = with_path(Path::Host, || with_products(ProductPrecision::Bf16, step));
        let expected = with_path(Path::Stock, step);
        // The state is a blend of values in [-1, 1]: the gates' and candidate's pre-activations
        // err by the products' rounding, which the sigmoid and tanh pass on at most as they are.
        let error = max_abs_diff(expected, got);
        eprintln!("GRU step {h}x{w}: {algorithm:?}, largest error {error:.2e}");
        assert!(error < 0.05, "{h}x{w}: {error}");
    }
}

/// The correlation pyramid's level 0 with bf16 products against burn's f32 `all_pairs`.
#[test]
fn the_correlation_with_bf16_products_meets_burns_f32() {
    unit_present("correlation");
    let device = Device::flex();
    let (n, c, h, w1, w2) = (2, 64, 5, 37, 29);
    let f1 = Tensor::<4>::random([n, c, h, w1], Distribution::Normal(0.0, 1.0), &device);
    let f2 = Tensor::<4>::random([n, c, h, w2], Distribution::Normal(0.0, 1.0), &device);
    let pyramid = with_path(Path::Host, || {
        with_products(ProductPrecision::Bf16, || CorrelationPyramid::new(f1.clone(), f2.clone(), 2, 4))
    });
    assert_eq!(pyramid.path(), Path::Host);
    let got = pyramid.levels().remove(0);
    let expected = with_path(Path::Stock, || all_pairs(f1.clone(), f2.clone())).reshape([n * h * w1, w2]);
    let magnitude = with_path(Path::Stock, || all_pairs(f1.abs(), f2.abs())).max().into_scalar::<f32>();
    let error = max_abs_diff(expected, got) / magnitude;
    eprintln!("correlation: error {error:.2e} of the largest sum of |products|");
    assert!(error < BOUND, "{error}");
}

/// A linear layer with bf16 products against burn's f32 layer: rows over several blocks (the
/// last one short), a depth and a width off the packing's steps, with a bias. In f32 the layer
/// is burn's own.
#[test]
fn linear_layers_with_bf16_products_meet_burns_f32() {
    let present = unit_present("linear");
    let device = Device::flex();
    let (b, n, d_in, d_out) = (2, 301, 72, 100);
    let linear = burn::nn::LinearConfig::new(d_in, d_out).init(&device);
    let x = Tensor::<3>::random([b, n, d_in], Distribution::Normal(0.0, 1.0), &device);
    let planned = |precision| with_products(precision, || crate::dispatch::plan(&device, &crate::dispatch::LinearCall));
    assert!(matches!(planned(ProductPrecision::F32), Plan::Stock), "f32 keeps burn's layer");
    assert_eq!(matches!(planned(ProductPrecision::Bf16), Plan::HostInference(_)), present);
    let got =
        with_path(Path::Host, || with_products(ProductPrecision::Bf16, || crate::linear_forward(&linear, x.clone())));
    let expected = linear.forward(x.clone());
    let magnitude = x.abs().matmul(linear.weight.val().abs().unsqueeze()).max().into_scalar::<f32>()
        + linear.bias.as_ref().map_or(0.0, |b| b.val().abs().max().into_scalar::<f32>());
    let error = max_abs_diff(expected, got) / magnitude;
    eprintln!("linear: error {error:.2e} of the largest sum of |products|");
    assert!(error < BOUND, "{error}");
    if present {
        assert!(error > 0.0, "the bf16 products round their inputs");
    }
}
