//! Convolution: `conv.forward(x)` and burn's `conv2d` with the fast path the dispatch picks.
//!
//! Every convolution of the stages goes through [`conv2d_forward`] (a module) or [`conv2d_op`]
//! (a weight tensor); the `_then` forms take element-wise work after the convolution, which the
//! host kernel and the GPU's product run while they write the output instead of in a pass of its
//! own. CPU inference takes the host kernel ([`crate::host::conv`]), GPU inference one matrix
//! product over gathered columns ([`crate::gpu::matmul_conv`]), autodiff burn's convolution.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor};

use crate::autodiff;
use crate::dispatch::{Op, Path, path};
use crate::gpu::matmul_conv::{conv2d_by_matmul, conv2d_by_matmul_then, suits_product};
use crate::host::conv::{conv2d_host, conv2d_host_rectified};

/// `conv.forward(x)`: the host kernel for CPU inference, one matrix product for stride-1
/// convolutions in GPU inference ([`crate::gpu::matmul_conv`]), burn's convolution elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_forward(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_module_macs(conv, x.dims()));
    match conv_options(conv) {
        Some(options) => conv2d_op(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), options),
        None => conv.forward(x),
    }
}

/// `relu(conv.forward(x))`: on CPU inference the host kernel applies the ReLU while it writes
/// the output (no extra pass), elsewhere [`conv2d_forward`] and a ReLU.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_relu_forward(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_module_macs(conv, x.dims()));
    match conv_options(conv) {
        Some(options) if host_inference(&x.device()) => {
            conv2d_host_rectified(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), &options, true)
        }
        _ => conv2d_forward_then(conv, x, crate::ops::norm::rectify),
    }
}

/// `conv`, then a per-channel affine map `y·scale[o] + shift[o]` (a frozen batch norm), then a
/// ReLU when `relu`: on the host path folded into the convolution (the scale into the weight, the
/// shift into the bias), so the kernel writes the normalised output at once; elsewhere
/// `stock(x)`, the caller's composition and the reference. `affine` gives `(scale, shift)`, each
/// `[O]`, and is called only where the fold runs.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_affine_or(
    conv: &Conv2d,
    x: Tensor<4>,
    affine: impl FnOnce() -> (Tensor<1>, Tensor<1>),
    relu: bool,
    stock: impl FnOnce(Tensor<4>) -> Tensor<4>,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_module_macs(conv, x.dims()));
    match conv_options(conv) {
        Some(options) if host_inference(&x.device()) => {
            let (scale, shift) = affine();
            let o = scale.dims()[0];
            let weight = conv.weight.val() * scale.clone().reshape([o, 1, 1, 1]);
            let bias = match &conv.bias {
                Some(b) => b.val() * scale + shift,
                None => shift,
            };
            conv2d_host_rectified(x, weight, Some(bias), &options, relu)
        }
        _ => stock(x),
    }
}

/// [`conv2d_forward`] followed by `then`, element-wise work on the output seen as
/// `[N, O, H_out·W_out]` (see [`conv2d_op_then`]).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_forward_then(conv: &Conv2d, x: Tensor<4>, then: impl FnOnce(Tensor<3>) -> Tensor<3>) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_module_macs(conv, x.dims()));
    match conv_options(conv) {
        Some(options) => conv2d_op_then(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), options, then),
        None => pixels_then(conv.forward(x), then),
    }
}

/// [`conv2d_op`] followed by `then`, element-wise work on the output seen as
/// `[N, O, H_out·W_out]` whose other operands the caller has flattened alike ([`flat_pixels`])
/// before the call. On the GPU's product route `then` runs in the product's own kernel
/// ([`crate::gpu::matmul_conv::conv2d_by_matmul_then`]); elsewhere after the convolution.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
/// - `then` maps `[N, O, H_out·W_out]` to the same shape
pub fn conv2d_op_then(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_macs(x.dims(), weight.dims(), &options));
    let [_, _, kh, kw] = weight.dims();
    match conv_path(&x.device(), &options, [kh, kw]) {
        Path::Gpu => conv2d_by_matmul_then(x, weight, bias, &options, then),
        Path::Host | Path::Stock => pixels_then(conv2d_op(x, weight, bias, options), then),
    }
}

/// `x` (`[N, C, H, W]`) as `[N, C, H·W]`, the shape [`conv2d_op_then`]'s `then` works on.
pub fn flat_pixels(x: Tensor<4>) -> Tensor<3> {
    let [n, c, h, w] = x.dims();
    x.reshape([n, c, h * w])
}

/// `then` on `x` seen as `[N, C, H·W]`, the result as `[N, C, H, W]`.
fn pixels_then(x: Tensor<4>, then: impl FnOnce(Tensor<3>) -> Tensor<3>) -> Tensor<4> {
    let dims = x.dims();
    then(flat_pixels(x)).reshape(dims)
}

/// The options of `conv` as the host kernel takes them; `None` for what it does not do (groups,
/// `Same` padding, which depends on the input size).
pub fn conv_options(conv: &Conv2d) -> Option<ConvOptions<2>> {
    let padding = match conv.padding {
        PaddingConfig2d::Explicit(top, left, bottom, right) => [(top, bottom), (left, right)],
        PaddingConfig2d::Valid => [(0, 0), (0, 0)],
        PaddingConfig2d::Same => return None,
    };
    (conv.groups == 1).then(|| ConvOptions::new_with_padding(conv.stride, padding, conv.dilation, 1))
}

/// burn's `conv2d(x, weight, bias, options)` as [`conv2d_forward`] chooses: the host kernel for
/// CPU inference (groups = 1), one matrix product for stride-1 convolutions in GPU inference
/// ([`crate::gpu::matmul_conv`]), burn's operation elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
pub fn conv2d_op(x: Tensor<4>, weight: Tensor<4>, bias: Option<Tensor<1>>, options: ConvOptions<2>) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_macs(x.dims(), weight.dims(), &options));
    let [_, _, kh, kw] = weight.dims();
    match conv_path(&x.device(), &options, [kh, kw]) {
        Path::Host if x.device().is_autodiff() && weight.dims()[1] >= autodiff::MIN_CHANNELS => {
            autodiff::conv2d(x, weight, bias, options)
        }
        Path::Host if x.device().is_autodiff() => conv2d(x, weight, bias, options),
        Path::Host => conv2d_host(x, weight, bias, &options),
        Path::Gpu => conv2d_by_matmul(x, weight, bias, &options),
        Path::Stock => conv2d(x, weight, bias, options),
    }
}

/// Whether the host kernel runs inference on `device`: the epilogues it fuses (ReLU, a folded
/// norm) have no backward of their own, so training composes them after the convolution.
fn host_inference(device: &Device) -> bool {
    path(device, Op::Conv) == Path::Host && !device.is_autodiff()
}

/// Where a convolution with `options` and a `kh x kw` kernel on `device` runs: the dispatch's
/// path where that path takes the shape (the host kernel: one group; the GPU's product: the
/// shapes [`suits_product`] names), burn's operation otherwise.
fn conv_path(device: &Device, options: &ConvOptions<2>, kernel: [usize; 2]) -> Path {
    match path(device, Op::Conv) {
        Path::Host if options.groups == 1 => Path::Host,
        Path::Gpu if suits_product(options, kernel) => Path::Gpu,
        _ => Path::Stock,
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::tensor::{max_abs_diff, to_vec};

    use super::*;

    #[test]
    fn module_forward_takes_the_host_kernel_only_for_cpu_inference() {
        use burn::module::Module;
        use burn::nn::conv::Conv2dConfig;
        let device = Device::flex();
        let conv = Conv2dConfig::new([4, 6], [3, 3]).with_padding(PaddingConfig2d::Explicit(1, 2, 1, 2)).init(&device);
        let x = Tensor::<4>::random([1, 4, 10, 12], Distribution::Normal(0.0, 1.0), &device);
        let diff = max_abs_diff(conv.forward(x.clone()), conv2d_forward(&conv, x.clone()));
        assert!(diff < 1e-5, "{diff}");
        // With autodiff the stock operation runs and gradients flow.
        let ad = device.autodiff();
        let conv_ad = conv.fork(&ad).train();
        let y = conv2d_forward(&conv_ad, Tensor::from_data(x.into_data(), &ad)).sum();
        let grads = y.backward();
        assert!(conv_ad.weight.grad(&grads).is_some());
    }

    #[test]
    fn the_relu_epilogue_equals_relu_after_the_convolution() {
        use burn::module::Module;
        use burn::nn::conv::Conv2dConfig;
        let device = Device::flex();
        let conv = Conv2dConfig::new([5, 7], [3, 3]).with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1)).init(&device);
        let x = Tensor::<4>::random([2, 5, 9, 11], Distribution::Normal(0.0, 1.0), &device);
        let expected = burn::tensor::activation::relu(conv.forward(x.clone()));
        let host = conv2d_relu_forward(&conv, x.clone());
        assert!(max_abs_diff(expected.clone(), host.clone()) < 1e-5);
        assert!(to_vec(host).contains(&0.0), "a random convolution has negative outputs");
        // The stock path (autodiff) too.
        let ad = device.clone().autodiff();
        let stock = conv2d_relu_forward(&conv.fork(&ad), Tensor::from_data(x.into_data(), &ad));
        assert!(max_abs_diff(expected, Tensor::from_data(stock.into_data(), &device)) < 1e-5);
    }

    crate::test_paths!(
        /// Every path computes burn's convolution module, plain and with the ReLU epilogue:
        /// 3x3 at stride 1 (Winograd's shapes on the host) and 2, 1x1, and a strided 7x7 stem.
        fn every_path_computes_burns_convolution(pinned) {
            use burn::nn::conv::Conv2dConfig;
            let device = Device::flex();
            for (k, stride, pad, [c, o]) in [(3, 1, 1, [32, 40]), (3, 2, 1, [8, 6]), (1, 1, 0, [16, 3]), (7, 2, 3, [3, 8])] {
                let conv = Conv2dConfig::new([c, o], [k, k])
                    .with_stride([stride, stride])
                    .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
                    .init(&device);
                let x = Tensor::<4>::random([2, c, 18, 20], Distribution::Normal(0.0, 1.0), &device);
                let expected = conv.forward(x.clone());
                let scale = expected.clone().abs().max().into_scalar::<f32>().max(1.0);
                let diff = max_abs_diff(expected.clone(), conv2d_forward(&conv, x.clone())) / scale;
                assert!(diff < 4e-5, "{pinned:?} {k}x{k} stride {stride}: {diff}");
                let rectified = burn::tensor::activation::relu(expected);
                let diff = max_abs_diff(rectified, conv2d_relu_forward(&conv, x)) / scale;
                assert!(diff < 4e-5, "{pinned:?} {k}x{k} stride {stride} relu: {diff}");
            }
        }
    );
}
