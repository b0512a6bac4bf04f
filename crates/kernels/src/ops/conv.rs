//! Convolution: `conv.forward(x)` and burn's `conv2d`, carried out as the dispatch plans.
//!
//! Every convolution of the stages goes through [`conv2d_forward`] (a module) or [`conv2d_op`]
//! (a weight tensor), each with the [`Numerics`] its caller allows; the `_relu` and `_then` forms
//! take element-wise work after the convolution, which the host kernel and the GPU's product run
//! while they write the output instead of in a pass of its own, and [`conv2d_affine`] a frozen
//! batch norm, which CPU inference folds into the convolution. All of them run one entry,
//! `convolve`, which asks the dispatch for the plan ([`crate::dispatch`]: the host kernel and its
//! algorithm, our training node, the GPU's product, or burn's convolution) and carries it out.

use burn::nn::conv::Conv2d;
use burn::tensor::Tensor;
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;

use crate::autodiff;
use crate::dispatch::{ConvCall, Numerics, Plan, plan};
use crate::geometry::Epilogue;
pub use crate::geometry::conv_options;
use crate::gpu::matmul_conv::{conv2d_by_matmul, conv2d_by_matmul_then};
use crate::host::conv::conv2d_host;
use crate::ops::norm::{affine_planes, rectify};

/// What follows a convolution inside its call.
enum After<F> {
    /// Nothing.
    Nothing,
    /// `max(0, ·)`: written by the host kernel as it writes the output.
    Relu,
    /// Element-wise work on the output seen as `[N, O, H_out·W_out]`.
    Then(F),
}

/// The one entry of every convolution of the face: the plan for `x` and `weight` with
/// `options` and `numerics`, carried out, then `after`.
fn convolve<F: FnOnce(Tensor<3>) -> Tensor<3>>(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    numerics: Numerics,
    after: After<F>,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_macs(x.dims(), weight.dims(), &options));
    let call = ConvCall { x_dims: x.dims(), w_dims: weight.dims(), options: &options, numerics };
    match plan(&x.device(), &call) {
        Plan::HostInference(algorithm) => match after {
            After::Relu => conv2d_host(x, weight, bias, &options, algorithm, Epilogue::Relu),
            after => finish(conv2d_host(x, weight, bias, &options, algorithm, Epilogue::Linear), after),
        },
        Plan::HostTraining(algorithms) => finish(autodiff::conv::conv2d(x, weight, bias, options, algorithms), after),
        Plan::Gpu(form) => match after {
            After::Nothing => conv2d_by_matmul(x, weight, bias, &options, form),
            After::Relu => conv2d_by_matmul_then(x, weight, bias, &options, form, rectify),
            After::Then(then) => conv2d_by_matmul_then(x, weight, bias, &options, form, then),
        },
        Plan::Stock => finish(conv2d(x, weight, bias, options), after),
    }
}

/// `after` on a convolution's output `y`, as its own operations.
fn finish<F: FnOnce(Tensor<3>) -> Tensor<3>>(y: Tensor<4>, after: After<F>) -> Tensor<4> {
    match after {
        After::Nothing => y,
        After::Relu => pixels_then(y, rectify),
        After::Then(then) => pixels_then(y, then),
    }
}

/// `after` on `conv.forward(x)`: the module's own convolution, for the options the face does not
/// take (groups, `Same` padding), or [`convolve`].
fn module_convolve<F: FnOnce(Tensor<3>) -> Tensor<3>>(
    conv: &Conv2d,
    x: Tensor<4>,
    numerics: Numerics,
    after: After<F>,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_module_macs(conv, x.dims()));
    match conv_options(conv) {
        Some(options) => convolve(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), options, numerics, after),
        None => finish(conv.forward(x), after),
    }
}

/// No element-wise work after a convolution.
type Nothing = fn(Tensor<3>) -> Tensor<3>;

/// `conv.forward(x)`, with the rounding `numerics` allows in training.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_forward(conv: &Conv2d, x: Tensor<4>, numerics: Numerics) -> Tensor<4> {
    module_convolve::<Nothing>(conv, x, numerics, After::Nothing)
}

/// `relu(conv.forward(x))`: on CPU inference the host kernel applies the ReLU while it writes
/// the output (no extra pass), on the GPU's product in its epilogue.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_relu_forward(conv: &Conv2d, x: Tensor<4>, numerics: Numerics) -> Tensor<4> {
    module_convolve::<Nothing>(conv, x, numerics, After::Relu)
}

/// [`conv2d_forward`] followed by `then`, element-wise work on the output seen as
/// `[N, O, H_out·W_out]` (see [`conv2d_op_then`]).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_forward_then(
    conv: &Conv2d,
    x: Tensor<4>,
    numerics: Numerics,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    module_convolve(conv, x, numerics, After::Then(then))
}

/// `conv`, then a frozen batch norm `y·scale[o] + shift[o]`, then a ReLU when `relu`: for CPU
/// inference folded into the convolution (the scale into the weight, the shift into the bias),
/// so the host kernel writes the normalised output at once; elsewhere the convolution and
/// [`affine_planes`].
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `scale`, `shift`: `[O]`; output `[N, O, H_out, W_out]`
pub fn conv2d_affine(
    conv: &Conv2d,
    x: Tensor<4>,
    [scale, shift]: [Tensor<1>; 2],
    relu: bool,
    numerics: Numerics,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::conv_module_macs(conv, x.dims()));
    if let Some(options) = conv_options(conv) {
        let call = ConvCall { x_dims: x.dims(), w_dims: conv.weight.dims(), options: &options, numerics };
        if let Plan::HostInference(algorithm) = plan(&x.device(), &call) {
            let o = scale.dims()[0];
            let weight = conv.weight.val() * scale.clone().reshape([o, 1, 1, 1]);
            let bias = match &conv.bias {
                Some(b) => b.val() * scale + shift,
                None => shift,
            };
            let epilogue = if relu { Epilogue::Relu } else { Epilogue::Linear };
            return conv2d_host(x, weight, Some(bias), &options, algorithm, epilogue);
        }
    }
    affine_planes(conv2d_forward(conv, x, numerics), scale, shift, relu)
}

/// burn's `conv2d(x, weight, bias, options)`, with the rounding `numerics` allows in training.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
pub fn conv2d_op(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    numerics: Numerics,
) -> Tensor<4> {
    convolve::<Nothing>(x, weight, bias, options, numerics, After::Nothing)
}

/// [`conv2d_op`] followed by `then`, element-wise work on the output seen as
/// `[N, O, H_out·W_out]` whose other operands the caller has flattened alike ([`flat_pixels`])
/// before the call. On the GPU's product `then` runs in the product's own kernel; elsewhere
/// after the convolution.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
/// - `then` maps `[N, O, H_out·W_out]` to the same shape
pub fn conv2d_op_then(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    numerics: Numerics,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    convolve(x, weight, bias, options, numerics, After::Then(then))
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

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::tensor::{max_abs_diff, to_vec};

    use super::*;
    use burn::nn::PaddingConfig2d;
    use burn::tensor::Device;

    #[test]
    fn module_forward_takes_the_host_kernel_only_for_cpu_inference() {
        use burn::module::Module;
        use burn::nn::conv::Conv2dConfig;
        let device = Device::flex();
        let conv = Conv2dConfig::new([4, 6], [3, 3]).with_padding(PaddingConfig2d::Explicit(1, 2, 1, 2)).init(&device);
        let x = Tensor::<4>::random([1, 4, 10, 12], Distribution::Normal(0.0, 1.0), &device);
        let diff = max_abs_diff(conv.forward(x.clone()), conv2d_forward(&conv, x.clone(), Numerics::Sensitive));
        assert!(diff < 1e-5, "{diff}");
        // With autodiff the stock operation runs and gradients flow.
        let ad = device.autodiff();
        let conv_ad = conv.fork(&ad).train();
        let y = conv2d_forward(&conv_ad, Tensor::from_data(x.into_data(), &ad), Numerics::Sensitive).sum();
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
        let host = conv2d_relu_forward(&conv, x.clone(), Numerics::Sensitive);
        assert!(max_abs_diff(expected.clone(), host.clone()) < 1e-5);
        assert!(to_vec(host).contains(&0.0), "a random convolution has negative outputs");
        // The stock path (autodiff) too.
        let ad = device.clone().autodiff();
        let stock = conv2d_relu_forward(&conv.fork(&ad), Tensor::from_data(x.into_data(), &ad), Numerics::Sensitive);
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
                let diff = max_abs_diff(expected.clone(), conv2d_forward(&conv, x.clone(), Numerics::Sensitive)) / scale;
                assert!(diff < 4e-5, "{pinned:?} {k}x{k} stride {stride}: {diff}");
                let rectified = burn::tensor::activation::relu(expected);
                let diff = max_abs_diff(rectified, conv2d_relu_forward(&conv, x, Numerics::Sensitive)) / scale;
                assert!(diff < 4e-5, "{pinned:?} {k}x{k} stride {stride} relu: {diff}");
            }
        }
    );
}
