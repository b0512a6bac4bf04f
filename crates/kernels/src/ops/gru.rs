//! The ConvGRU step: on the host path one fused host step ([`crate::host::gru`]); elsewhere the
//! caller's composition of burn's operations, the reference.

use burn::nn::conv::Conv2d;
use burn::tensor::Tensor;

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
    if path(&h.device(), Op::GruStep) == Path::Host
        && let Some(next) = gru::step(convs, h.clone(), contexts, inputs)
    {
        return next;
    }
    stock(h)
}
