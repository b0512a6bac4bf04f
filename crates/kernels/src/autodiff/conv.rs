//! The convolution with our backward: the forward runs the host convolution on the inner Flex
//! tensors and registers a node whose backward computes the gradients of the input, the weight
//! and the bias on host buffers (`crate::host::conv_backward`).

use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::ops::ModuleOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, backend_extension};
use burn::tensor::ops::ConvOptions;
use burn::tensor::{DType, Tensor};

use super::{dims4, flex, values};

use crate::algorithm::ConvTraining;
use crate::geometry::Epilogue;
use crate::host::conv::conv2d_host_slices;
use crate::host::conv_backward::{
    conv2d_bias_grad, conv2d_input_grad, conv2d_weight_grad, conv2d_weight_grad_winograd,
};

/// The convolution whose backward is the host kernels'.
#[backend_extension(Flex, Autodiff)]
pub trait HostConvBackend: Backend {
    /// `conv2d(x, weight, bias)` with `options` (one group) by the `algorithms` the dispatch
    /// chose.
    fn host_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
        algorithms: ConvTraining,
    ) -> FloatTensor<Self>;
}

/// The host convolution of Flex tensors, by the forward's algorithm.
fn forward(
    x: &FlexTensor,
    weight: &FlexTensor,
    bias: &FlexTensor,
    options: &ConvOptions<2>,
    algorithms: &ConvTraining,
) -> FlexTensor {
    let (xv, wv, bv) = (values(x), values(weight), values(bias));
    let (x_dims, w_dims) = (dims4(x), dims4(weight));
    let (out, dims) =
        conv2d_host_slices(&xv, x_dims, &wv, w_dims, Some(&bv), options, algorithms.forward, Epilogue::Linear);
    flex(out, &dims)
}

impl HostConvBackend for Flex {
    fn host_conv2d(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        options: ConvOptions<2>,
        algorithms: ConvTraining,
    ) -> FlexTensor {
        forward(&x, &weight, &bias, &options, &algorithms)
    }
}

/// The backward node of [`HostConvBackend::host_conv2d`].
#[derive(Debug)]
struct HostConv2d;

impl Backward<Flex, 3> for HostConv2d {
    type State = (NodeId, NodeId, ConvOptions<2>, ConvTraining);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, checkpointer: &mut Checkpointer) {
        let [node_x, node_weight, node_bias] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let (x_state, weight_state, options, algorithms) = ops.state;
        let x: FlexTensor = checkpointer.retrieve_node_output(x_state);
        let weight: FlexTensor = checkpointer.retrieve_node_output(weight_state);
        let (x_dims, w_dims, g_dims) = (dims4(&x), dims4(&weight), dims4(&grad));
        let gv = values(&grad);
        if let Some(node) = node_x {
            let host = algorithms
                .input_grad
                .and_then(|a| conv2d_input_grad(&gv, g_dims, &values(&weight), w_dims, x_dims, &options, a));
            let dx = match host {
                Some(dx) => flex(dx, &x_dims),
                None => Flex::conv2d_x_backward(x.clone(), weight.clone(), grad.clone(), options.clone()),
            };
            grads.register::<Flex>(node.id, dx);
        }
        if let Some(node) = node_weight {
            let xv = values(&x);
            let dw = match algorithms.weight_grad {
                Some(tile) => conv2d_weight_grad_winograd(&xv, x_dims, &gv, w_dims, &options, tile),
                None => conv2d_weight_grad(&xv, x_dims, &gv, w_dims, &options),
            };
            grads.register::<Flex>(node.id, flex(dw, &w_dims));
        }
        if let Some(node) = node_bias {
            let [n, o, h, w] = g_dims;
            grads.register::<Flex>(node.id, flex(conv2d_bias_grad(&gv, [n, o, h * w]), &[o]));
        }
    }
}

impl<C: CheckpointStrategy> HostConvBackend for Autodiff<Flex, C> {
    fn host_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
        algorithms: ConvTraining,
    ) -> FloatTensor<Self> {
        match HostConv2d.prepare::<C>([x.node(), weight.node(), bias.node()]).compute_bound().stateful() {
            OpsKind::Tracked(mut prep) => {
                let x_state = prep.checkpoint(&x);
                let weight_state = prep.checkpoint(&weight);
                let out = forward(x.primitive(), weight.primitive(), bias.primitive(), &options, &algorithms);
                prep.finish((x_state, weight_state, options, algorithms), out)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(forward(x.primitive(), weight.primitive(), bias.primitive(), &options, &algorithms))
            }
        }
    }
}

/// `conv2d(x, weight, bias)` with `options` (one group) on the Flex autodiff device, float32, by
/// the `algorithms` the dispatch chose, its gradients from the host kernels; `bias` zeros where
/// the convolution has none (a constant, so no gradient is computed for it).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
pub(crate) fn conv2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    algorithms: ConvTraining,
) -> Tensor<4> {
    debug_assert_eq!(x.dtype(), DType::F32);
    let bias = bias.unwrap_or_else(|| Tensor::zeros([weight.dims()[0]], &x.device()));
    let out = <burn::backend::Dispatch as HostConvBackend>::host_conv2d(
        x.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        options,
        algorithms,
    );
    Tensor::from_dispatch(out)
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d as burn_conv2d;
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::to_vec;

    use super::*;
    use crate::Numerics;
    use crate::dispatch::training_algorithms;
    use crate::settings::settings;

    /// The training algorithms the dispatch gives the shape with `numerics`.
    fn algorithms(x: &Tensor<4>, w: &Tensor<4>, options: &ConvOptions<2>, numerics: Numerics) -> ConvTraining {
        training_algorithms(x.dims(), w.dims(), options, numerics, settings())
    }

    /// The largest difference of two gradients relative to the reference's largest magnitude.
    fn relative(got: Tensor<4>, want: Tensor<4>) -> f32 {
        let (got, want) = (to_vec(got), to_vec(want));
        let scale = want.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale
    }

    /// With tolerant numerics the training forward of a 64-channel layer takes Winograd (its sums
    /// differ from the plain products' in rounding) and still agrees with burn's convolution;
    /// with sensitive ones it keeps the plain products.
    #[test]
    fn tolerant_numerics_take_winograd_in_the_training_forward() {
        let ad = Device::flex().autodiff();
        let x = Tensor::<4>::random([1, 64, 40, 48], Distribution::Normal(0.0, 1.0), &ad);
        let w = Tensor::<4>::random([64, 64, 3, 3], Distribution::Normal(0.0, 0.05), &ad);
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        let run = |numerics| {
            let algorithms = algorithms(&x, &w, &options, numerics);
            to_vec(conv2d(x.clone(), w.clone(), None, options.clone(), algorithms))
        };
        let outside = run(Numerics::Sensitive);
        let inside = run(Numerics::Tolerant);
        let want = to_vec(burn_conv2d(x.clone(), w.clone(), None, options.clone()));
        let scale = want.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        let worst = |got: &[f32]| got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale;
        assert!(worst(&outside) < 1e-5 && worst(&inside) < 4e-5, "{} {}", worst(&outside), worst(&inside));
        assert_ne!(inside, outside, "the tolerant forward took the plain products");
    }

    /// The gradients of the input, the weight and the bias against burn's own autodiff of
    /// `conv2d`, with a random output gradient (the loss `Σ conv·r`): 3x3 stride 1 with enough
    /// channels for Winograd in the input gradient (and, at 256 input channels, in the forward
    /// and, with 32 outputs, the weight gradient too), few channels, asymmetric and no padding, a
    /// 1x1, a strided 7x7 stem and a strided 3x3 (burn's input gradient), without a bias.
    #[test]
    fn gradients_agree_with_burns_autodiff() {
        let ad = Device::flex().autodiff();
        /// Batch, `[C, O]`, kernel, stride, padding, bias.
        type Case = (usize, [usize; 2], [usize; 2], usize, [(usize, usize); 2], bool);
        let cases: [Case; 10] = [
            (2, [24, 32], [1, 1], 2, [(0, 0), (0, 0)], true),
            (1, [crate::dispatch::TRAINING_WINOGRAD_MIN_CHANNELS, 16], [3, 3], 1, [(1, 1), (1, 1)], true),
            (1, [crate::dispatch::TRAINING_WINOGRAD_MIN_CHANNELS, 32], [3, 3], 1, [(1, 1), (1, 1)], false),
            (2, [64, 48], [3, 3], 1, [(1, 1), (1, 1)], true),
            (1, [5, 7], [3, 3], 1, [(1, 1), (1, 1)], true),
            (2, [4, 6], [3, 3], 1, [(0, 2), (1, 0)], true),
            (1, [6, 3], [3, 3], 1, [(0, 0), (0, 0)], false),
            (2, [16, 8], [1, 1], 1, [(0, 0), (0, 0)], true),
            (1, [3, 8], [7, 7], 2, [(3, 3), (3, 3)], true),
            (1, [8, 12], [3, 3], 2, [(1, 1), (1, 1)], false),
        ];
        for (n, [c, o], [kh, kw], stride, padding, with_bias) in cases {
            let options = ConvOptions::new_with_padding([stride; 2], padding, [1, 1], 1);
            let rand = |dims: [usize; 4], std: f64| Tensor::<4>::random(dims, Distribution::Normal(0.0, std), &ad);
            let x = rand([n, c, 19, 23], 1.0);
            let w = rand([o, c, kh, kw], 0.3);
            let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &ad);
            let run = |ours: bool| {
                let (x, w, b) = (
                    x.clone().detach().require_grad(),
                    w.clone().detach().require_grad(),
                    b.clone().detach().require_grad(),
                );
                let bias = with_bias.then(|| b.clone());
                let y = if ours {
                    let algorithms = algorithms(&x, &w, &options, Numerics::Sensitive);
                    conv2d(x.clone(), w.clone(), bias, options.clone(), algorithms)
                } else {
                    burn_conv2d(x.clone(), w.clone(), bias, options.clone())
                };
                let r = Tensor::<4>::ones(y.dims(), &ad).mul_scalar(0.5) + y.clone().detach().sin();
                let grads = (y.clone() * r).sum().backward();
                let gb = with_bias.then(|| b.grad(&grads).expect("bias gradient"));
                (y.detach(), x.grad(&grads).expect("input gradient"), w.grad(&grads).expect("weight gradient"), gb)
            };
            let (y0, gx0, gw0, gb0) = run(false);
            let (y1, gx1, gw1, gb1) = run(true);
            let case = format!("n {n} c {c} o {o} {kh}x{kw} stride {stride} padding {padding:?}");
            let plain = |t: Tensor<4>| Tensor::<4>::from_data(t.into_data(), &Device::flex());
            assert!(relative(plain(y1), plain(y0)) < 4e-5, "{case}: forward");
            assert!(relative(plain(gx1), plain(gx0)) < 4e-5, "{case}: input gradient");
            assert!(relative(plain(gw1), plain(gw0)) < 1e-5, "{case}: weight gradient");
            if let (Some(a), Some(b)) = (gb1, gb0) {
                let (a, b) = (to_vec(a), to_vec(b));
                let worst = a.iter().zip(&b).map(|(a, b)| (a - b).abs() / b.abs().max(1.0)).fold(0.0, f32::max);
                assert!(worst < 1e-5, "{case}: bias gradient {worst}");
            }
        }
    }
}
