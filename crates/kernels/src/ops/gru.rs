//! The ConvGRU step, `h' = (1 - z)·h + z·tanh(convq([r·h, x]) + cq)` with
//! `z = σ(convz([h, x]) + cz)`, `r = σ(convr([h, x]) + cr)`.
//!
//! Design decision: one face operation for the whole step, so that each path can arrange it as it
//! runs best: for CPU inference one fused host step (`crate::host::gru`: two parallel passes
//! around the two convolutions, Winograd's transforms of `x` shared between them); elsewhere the
//! tensor-op step below, the reference, whose gates and blend are nodes with our backward in
//! training on the host path, and which on the GPU gathers the inputs' columns once for both
//! convolutions (`crate::gpu::matmul_conv::SharedColumns`). The update and reset gates read the
//! same input `[h, x]`, so they run as one convolution with `2·hidden` outputs (the weights of
//! `convz` and `convr` concatenated at each call, a few MB next to a multi-GMAC convolution),
//! which halves the column work and gives the product a wider output.

use burn::nn::conv::Conv2d;
use burn::tensor::Tensor;
use burn::tensor::activation::{sigmoid, tanh};

use crate::algorithm::GpuConvForm;
use crate::autodiff;
use crate::dispatch::{GruStepCall, NodeCall, Numerics, Op, Plan, plan};
use crate::gpu::matmul_conv::SharedColumns;
use crate::host::gru;
use crate::ops::conv::{conv2d_forward_then, conv2d_op_then, flat_pixels};

/// One ConvGRU step of `convs` (`convz`, `convr`, `convq`) from the state `h`, with `x` the
/// concatenation of `inputs`, `zr_ctx` the gates' context `[cz, cr]` and `q_ctx` the
/// candidate's; its convolutions take the rounding `numerics` allows in training.
///
/// # Shapes
/// - `h`, `q_ctx`: `[N, C, H, W]`; `zr_ctx`: `[N, 2·C, H, W]`; `inputs[i]`: `[N, C_i, H, W]`;
///   output `[N, C, H, W]`
pub fn conv_gru_step(
    convs: [&Conv2d; 3],
    h: Tensor<4>,
    contexts: [&Tensor<4>; 2],
    inputs: &[Tensor<4>],
    numerics: Numerics,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::gru_step_macs(convs, h.dims()));
    let input_channels = inputs.iter().map(|t| t.dims()[1]).sum();
    let call = GruStepCall::new(convs, h.dims(), input_channels);
    match plan(&h.device(), &call) {
        Plan::HostInference(algorithm) => match gru::step(convs, h.clone(), contexts, inputs, algorithm) {
            Some(next) => next,
            None => tensor_step(convs, h, contexts, inputs, numerics, None),
        },
        Plan::Gpu(form) => tensor_step(convs, h, contexts, inputs, numerics, Some(form)),
        Plan::HostTraining(()) | Plan::Stock => tensor_step(convs, h, contexts, inputs, numerics, None),
    }
}

/// The step in tensor operations (the reference, and the training path); on the GPU with the
/// inputs' columns gathered once for both convolutions in the dispatch's `shared_columns` form.
fn tensor_step(
    [convz, convr, convq]: [&Conv2d; 3],
    h: Tensor<4>,
    [zr_ctx, q_ctx]: [&Tensor<4>; 2],
    inputs: &[Tensor<4>],
    numerics: Numerics,
    shared_columns: Option<GpuConvForm>,
) -> Tensor<4> {
    let hidden = h.dims()[1];
    // `[h, x]` and `[r·h, x]` each as one concatenation of all parts (no `x` of its own: one
    // copy fewer a step).
    let with_inputs = |first: Tensor<4>| Tensor::cat([first].into_iter().chain(inputs.iter().cloned()).collect(), 1);
    // The gates' context, the activations and the blend are each convolution's epilogue, on
    // `[N, C, H·W]` with their operands flattened before it (GPU inference runs them in the
    // product's kernel).
    let gate_options = GruStepCall::gate_options(convz);
    let shared = shared_columns.filter(|_| !inputs.is_empty()).map(|form| {
        let [_, _, kh, kw] = convz.weight.dims();
        let x = if inputs.len() == 1 { inputs[0].clone() } else { Tensor::cat(inputs.to_vec(), 1) };
        SharedColumns::gather(x, [kh, kw], &gate_options, form)
    });
    let zr_context = flat_pixels(zr_ctx.clone());
    let gates = |zr: Tensor<3>| gru_gates(zr, zr_context);
    let (weight, bias) = gate_weights(convz, convr);
    let zr = match &shared {
        Some(shared) => shared.conv_then(h.clone(), weight, bias, gates),
        None => conv2d_op_then(with_inputs(h.clone()), weight, bias, gate_options, numerics, gates),
    };
    let z = flat_pixels(zr.clone().narrow(1, 0, hidden));
    let r = zr.narrow(1, hidden, hidden);
    let (h_flat, q_context) = (flat_pixels(h.clone()), flat_pixels(q_ctx.clone()));
    let blend = |q: Tensor<3>| gru_blend(q, q_context, z, h_flat);
    match shared {
        Some(shared) => {
            let bias = convq.bias.as_ref().map(|b| b.val());
            shared.conv_then(r * h, convq.weight.val(), bias, blend)
        }
        None => conv2d_forward_then(convq, with_inputs(r * h), numerics, blend),
    }
}

/// The weights and biases of `convz` and `convr` stacked along the output channels: the one
/// convolution of both gates.
///
/// # Shapes
/// - weight `[2·hidden, hidden + input_dim, kh, kw]`; bias `[2·hidden]`
fn gate_weights(convz: &Conv2d, convr: &Conv2d) -> (Tensor<4>, Option<Tensor<1>>) {
    let weight = Tensor::cat(vec![convz.weight.val(), convr.weight.val()], 0);
    let bias = match (&convz.bias, &convr.bias) {
        (Some(bz), Some(br)) => Some(Tensor::cat(vec![bz.val(), br.val()], 0)),
        _ => None,
    };
    (weight, bias)
}

/// The GRU's gates `σ(pre + context)`: in training on the host path one node with our backward
/// (`crate::autodiff::gru`), burn's operations elsewhere.
fn gru_gates<const D: usize>(pre: Tensor<D>, context: Tensor<D>) -> Tensor<D> {
    match plan(&pre.device(), &NodeCall(Op::GruStep)) {
        Plan::HostTraining(()) => autodiff::gru::gates(pre, context),
        Plan::HostInference(()) | Plan::Gpu(()) | Plan::Stock => sigmoid(pre + context),
    }
}

/// The GRU's new state `(1 − z)·h + z·tanh(pre + context)`: in training on the host path one
/// node with our backward (`crate::autodiff::gru`), burn's operations elsewhere.
fn gru_blend<const D: usize>(pre: Tensor<D>, context: Tensor<D>, z: Tensor<D>, h: Tensor<D>) -> Tensor<D> {
    match plan(&pre.device(), &NodeCall(Op::GruStep)) {
        Plan::HostTraining(()) => autodiff::gru::blend(pre, context, z, h),
        Plan::HostInference(()) | Plan::Gpu(()) | Plan::Stock => {
            let q = tanh(pre + context);
            (z.clone().neg().add_scalar(1.0)) * h + z * q
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::max_abs_diff;

    use super::*;
    use crate::dispatch::{Path, with_path};

    /// In training the host path's gates and blend give burn's values and gradients of every
    /// input (the loss `Σ y·r`, a random `r`).
    #[test]
    fn training_nodes_agree_with_burns_autodiff() {
        let ad = Device::flex().autodiff();
        let rand = |std: f64| Tensor::<3>::random([2, 6, 37], Distribution::Normal(0.0, std), &ad);
        let (pre_zr, ctx_zr, pre_q, ctx_q, h) = (rand(2.0), rand(1.0), rand(2.0), rand(1.0), rand(1.0));
        let r = rand(1.0);
        let plain = |t: Tensor<3>| Tensor::<3>::from_data(t.into_data(), &Device::flex());
        let run = |pinned: Path| {
            let leaves = [&pre_zr, &ctx_zr, &pre_q, &ctx_q, &h].map(|t| t.clone().detach().require_grad());
            let [a, b, q, c, h] = leaves.clone();
            let (gates, state) = with_path(pinned, || {
                let gates = gru_gates(a, b);
                let z = gates.clone().narrow(1, 0, 3).repeat_dim(1, 2);
                (gates.clone(), gru_blend(q, c, z, h))
            });
            let grads = ((gates.clone() * r.clone()).sum() + (state.clone() * r.clone()).sum()).backward();
            let mut out = vec![plain(gates.detach()), plain(state.detach())];
            out.extend(leaves.iter().map(|l| plain(l.grad(&grads).expect("a gradient"))));
            out
        };
        let (stock, host) = (run(Path::Stock), run(Path::Host));
        for (i, (a, b)) in stock.into_iter().zip(host).enumerate() {
            assert!(max_abs_diff(a, b) < 2e-6, "output or gradient {i}");
        }
    }

    crate::test_paths!(
        /// The step on every path against its definition in burn's operations: a state whose
        /// convolutions take Winograd's shared transforms on the host (32 channels, 12x18), one
        /// that takes im2col (4 channels), two inputs and a batch of two.
        fn the_step_follows_its_definition(path) {
            use burn::nn::PaddingConfig2d;
            use burn::nn::conv::Conv2dConfig;
            use burn::tensor::module::conv2d;

            let device = Device::flex();
            for (n, hidden, input_channels, [h, w]) in [(1, 32, [16, 24], [12, 18]), (2, 4, [3, 5], [5, 7])] {
                let inputs_total: usize = input_channels.iter().sum();
                // Each call initialises its own random weights and biases.
                let conv = || {
                    Conv2dConfig::new([hidden + inputs_total, hidden], [3, 3])
                        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                        .init(&device)
                };
                let (convz, convr, convq) = (conv(), conv(), conv());
                let normal = |shape: [usize; 4]| Tensor::<4>::random(shape, Distribution::Normal(0.0, 1.0), &device);
                let state = normal([n, hidden, h, w]);
                let inputs: Vec<Tensor<4>> = input_channels.iter().map(|&c| normal([n, c, h, w])).collect();
                let (zr_ctx, q_ctx) = (normal([n, 2 * hidden, h, w]), normal([n, hidden, h, w]));
                let got = conv_gru_step(
                    [&convz, &convr, &convq],
                    state.clone(),
                    [&zr_ctx, &q_ctx],
                    &inputs,
                    Numerics::Sensitive,
                );
                let options = GruStepCall::gate_options(&convz);
                let plain = |conv: &Conv2d, x: Tensor<4>| {
                    conv2d(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), options.clone())
                };
                let with_inputs = |first: Tensor<4>| Tensor::cat([first].into_iter().chain(inputs.clone()).collect(), 1);
                let z = sigmoid(plain(&convz, with_inputs(state.clone())) + zr_ctx.clone().narrow(1, 0, hidden));
                let r = sigmoid(plain(&convr, with_inputs(state.clone())) + zr_ctx.narrow(1, hidden, hidden));
                let q = tanh(plain(&convq, with_inputs(r * state.clone())) + q_ctx);
                let want = (z.clone().neg().add_scalar(1.0)) * state + z * q;
                let err = max_abs_diff(got, want);
                assert!(err < 2e-5, "{path:?} n {n} hidden {hidden}: {err}");
            }
        }
    );
}
