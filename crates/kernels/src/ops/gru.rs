//! The ConvGRU step: for CPU inference one fused host step ([`crate::host::gru`]); elsewhere the
//! caller's composition of burn's operations, the reference, whose gates and blend
//! ([`gru_gates`], [`gru_blend`]) are nodes with our backward in training on the host path.

use burn::nn::conv::Conv2d;
use burn::tensor::Tensor;
use burn::tensor::activation::{sigmoid, tanh};

use crate::autodiff;
use crate::dispatch::{Op, Path, path};
use crate::host::gru;

/// One ConvGRU step `h' = (1 - z)·h + z·tanh(convq([r·h, x]) + cq)` (`x` the concatenation of
/// `inputs`, `zr_ctx` the gates' context `[cz, cr]`, `q_ctx` the candidate's) by the fused host
/// step where the dispatch takes the host path and the convolutions suit it; `stock()`, the
/// caller's tensor-op step, otherwise.
///
/// # Shapes
/// - `h`, `q_ctx`: `[N, C, H, W]`; `zr_ctx`: `[N, 2·C, H, W]`; `inputs[i]`: `[N, C_i, H, W]`;
///   output `[N, C, H, W]`
pub fn conv_gru_step_or(
    convs: [&Conv2d; 3],
    h: Tensor<4>,
    contexts: [&Tensor<4>; 2],
    inputs: &[Tensor<4>],
    stock: impl FnOnce(Tensor<4>) -> Tensor<4>,
) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::gru_step_macs(convs, h.dims()));
    let device = h.device();
    if path(&device, Op::GruStep) == Path::Host
        && !device.is_autodiff()
        && let Some(next) = gru::step(convs, h.clone(), contexts, inputs)
    {
        return next;
    }
    stock(h)
}

/// The GRU's gates `σ(pre + context)`: in training on the host path one node with our backward
/// ([`autodiff::gru`]), burn's operations elsewhere.
pub fn gru_gates<const D: usize>(pre: Tensor<D>, context: Tensor<D>) -> Tensor<D> {
    let device = pre.device();
    match path(&device, Op::GruStep) {
        Path::Host if device.is_autodiff() => autodiff::gru::gates(pre, context),
        _ => sigmoid(pre + context),
    }
}

/// The GRU's new state `(1 − z)·h + z·tanh(pre + context)`: in training on the host path one
/// node with our backward ([`autodiff::gru`]), burn's operations elsewhere.
pub fn gru_blend<const D: usize>(pre: Tensor<D>, context: Tensor<D>, z: Tensor<D>, h: Tensor<D>) -> Tensor<D> {
    let device = pre.device();
    match path(&device, Op::GruStep) {
        Path::Host if device.is_autodiff() => autodiff::gru::blend(pre, context, z, h),
        _ => {
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
    use crate::dispatch::with_path;

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
}
