//! The convolution with our backward: the forward runs the host convolution on the inner Flex
//! tensors and registers a node whose backward computes the gradients of the input, the weight
//! and the bias on host buffers ([`crate::host::conv_backward`]).

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

use super::winograd_region::WinogradForward;
use super::{dims4, flex, values};

use crate::host::conv::{conv2d_host_direct_slices, conv2d_host_slices};
use crate::host::conv_backward::{
    conv2d_bias_grad, conv2d_input_grad, conv2d_weight_grad, conv2d_weight_grad_winograd,
};

/// Fewest input channels for which training takes [`conv2d`]. The stems (3 input channels, a 7x7
/// kernel at stride 2, each followed by an instance or batch norm) keep burn's: with ours the
/// official training step's check failed on gradients of the feature encoder, whose instance
/// norms magnify a different summation order in the stem's output (worst gradient 1.5e-3
/// relative where the check allows 1e-3), and they are a small share of a step.
pub const MIN_CHANNELS: usize = 16;

/// The convolution whose backward is the host kernels'.
#[backend_extension(Flex, Autodiff)]
pub trait HostConvBackend: Backend {
    /// `conv2d(x, weight, bias)` with `options` (one group).
    fn host_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;
}

/// Fewest input channels for which the training forward takes Winograd outside a
/// [`WinogradForward`] region (inside one, every layer that suits it does): the ConvGRUs' gate and
/// candidate convolutions (256 or 384 input channels, most of an update iteration's products). The
/// feature encoder's layers (at most 128 input channels) keep plain products, whose rounding its
/// instance norms magnify (see `conv2d_host_direct_slices`; with Winograd from 128 channels the
/// official training step's worst gradient, `fnet.layer1.0.conv1`'s, rose from 1.789e-3 to
/// 1.948e-3 of the 3e-3 it allows, and the step was no faster). The weight gradient takes Winograd wherever the layer suits it
/// (`conv2d_weight_grad_winograd`): a weight's gradient feeds no other gradient, so its rounding is
/// not magnified.
pub const WINOGRAD_MIN_CHANNELS: usize = 256;

/// The host convolution of Flex tensors.
fn forward(x: &FlexTensor, weight: &FlexTensor, bias: &FlexTensor, options: &ConvOptions<2>) -> FlexTensor {
    let (xv, wv, bv) = (values(x), values(weight), values(bias));
    let (x_dims, w_dims) = (dims4(x), dims4(weight));
    let winograd = x_dims[1] >= WINOGRAD_MIN_CHANNELS || WinogradForward::active();
    let conv = if winograd { conv2d_host_slices } else { conv2d_host_direct_slices };
    let (out, dims) = conv(&xv, x_dims, &wv, w_dims, Some(&bv), options);
    flex(out, &dims)
}

impl HostConvBackend for Flex {
    fn host_conv2d(x: FlexTensor, weight: FlexTensor, bias: FlexTensor, options: ConvOptions<2>) -> FlexTensor {
        forward(&x, &weight, &bias, &options)
    }
}

/// The backward node of [`HostConvBackend::host_conv2d`].
#[derive(Debug)]
struct HostConv2d;

impl Backward<Flex, 3> for HostConv2d {
    type State = (NodeId, NodeId, ConvOptions<2>);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, checkpointer: &mut Checkpointer) {
        let [node_x, node_weight, node_bias] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let (x_state, weight_state, options) = ops.state;
        let x: FlexTensor = checkpointer.retrieve_node_output(x_state);
        let weight: FlexTensor = checkpointer.retrieve_node_output(weight_state);
        let (x_dims, w_dims, g_dims) = (dims4(&x), dims4(&weight), dims4(&grad));
        let gv = values(&grad);
        if let Some(node) = node_x {
            let host = conv2d_input_grad(&gv, g_dims, &values(&weight), w_dims, x_dims, &options);
            let dx = match host {
                Some(dx) => flex(dx, &x_dims),
                None => Flex::conv2d_x_backward(x.clone(), weight.clone(), grad.clone(), options.clone()),
            };
            grads.register::<Flex>(node.id, dx);
        }
        if let Some(node) = node_weight {
            let xv = values(&x);
            let winograd = conv2d_weight_grad_winograd(&xv, x_dims, &gv, w_dims, &options);
            let dw = winograd.unwrap_or_else(|| conv2d_weight_grad(&xv, x_dims, &gv, w_dims, &options));
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
    ) -> FloatTensor<Self> {
        match HostConv2d.prepare::<C>([x.node(), weight.node(), bias.node()]).compute_bound().stateful() {
            OpsKind::Tracked(mut prep) => {
                let x_state = prep.checkpoint(&x);
                let weight_state = prep.checkpoint(&weight);
                let out = forward(x.primitive(), weight.primitive(), bias.primitive(), &options);
                prep.finish((x_state, weight_state, options), out)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(forward(x.primitive(), weight.primitive(), bias.primitive(), &options))
            }
        }
    }
}

/// `conv2d(x, weight, bias)` with `options` (one group) on the Flex autodiff device, float32, its
/// gradients from the host kernels; `bias` zeros where the convolution has none (a constant, so
/// no gradient is computed for it).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
pub fn conv2d(x: Tensor<4>, weight: Tensor<4>, bias: Option<Tensor<1>>, options: ConvOptions<2>) -> Tensor<4> {
    debug_assert_eq!(x.dtype(), DType::F32);
    let bias = bias.unwrap_or_else(|| Tensor::zeros([weight.dims()[0]], &x.device()));
    let out = <burn::backend::Dispatch as HostConvBackend>::host_conv2d(
        x.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        options,
    );
    Tensor::from_dispatch(out)
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d as burn_conv2d;
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::to_vec;

    use super::*;

    /// The largest difference of two gradients relative to the reference's largest magnitude.
    fn relative(got: Tensor<4>, want: Tensor<4>) -> f32 {
        let (got, want) = (to_vec(got), to_vec(want));
        let scale = want.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale
    }

    /// Inside an update loop the training forward of a 64-channel layer takes Winograd (its sums
    /// differ from the plain products' in rounding) and still agrees with burn's convolution;
    /// outside one it keeps the plain products.
    #[test]
    fn an_update_loop_takes_winograd_in_the_training_forward() {
        let ad = Device::flex().autodiff();
        let x = Tensor::<4>::random([1, 64, 40, 48], Distribution::Normal(0.0, 1.0), &ad);
        let w = Tensor::<4>::random([64, 64, 3, 3], Distribution::Normal(0.0, 0.05), &ad);
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        let run = || to_vec(conv2d(x.clone(), w.clone(), None, options.clone()));
        let outside = run();
        let inside = {
            let _update_loop = crate::host::winograd::UpdateLoop::new();
            run()
        };
        let want = to_vec(burn_conv2d(x.clone(), w.clone(), None, options.clone()));
        let scale = want.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        let worst = |got: &[f32]| got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale;
        assert!(worst(&outside) < 1e-5 && worst(&inside) < 4e-5, "{} {}", worst(&outside), worst(&inside));
        assert_ne!(inside, outside, "the update loop's forward took the plain products");
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
            (1, [WINOGRAD_MIN_CHANNELS, 16], [3, 3], 1, [(1, 1), (1, 1)], true),
            (1, [WINOGRAD_MIN_CHANNELS, 32], [3, 3], 1, [(1, 1), (1, 1)], false),
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
                    conv2d(x.clone(), w.clone(), bias, options.clone())
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
