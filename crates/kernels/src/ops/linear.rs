//! Linear layers: `linear.forward(x)`, carried out as the dispatch plans.
//!
//! Only CPU inference with bf16 products has a kernel of its own ([`crate::host::linear`]): in
//! f32 burn's matrix product is as fast as ours, and training and the GPU keep burn's layer.

use burn::nn::Linear;
use burn::tensor::Tensor;
use dgstereo_core::tensor::{from_vec, host_values};

use crate::dispatch::{LinearCall, Plan, plan};
use crate::host::linear::linear_bf16;

/// `linear.forward(x)` over the last axis of `x` (`[B, N, d_in]` -> `[B, N, d_out]`), its product
/// in bf16 with f32 sums where the calling thread asks for bf16 products and the processor has a
/// unit ([`crate::ProductPrecision::Bf16`]).
pub fn linear_forward(linear: &Linear, x: Tensor<3>) -> Tensor<3> {
    let [b, n, d_in] = x.dims();
    let weight = linear.weight.val();
    let [_, d_out] = weight.dims();
    let _work = crate::work::operation(|| crate::work::linear_macs(b * n, [d_in, d_out]));
    let device = x.device();
    match plan(&device, &LinearCall) {
        Plan::HostInference(unit) => {
            let bias = linear.bias.as_ref().map(|b| host_values(b.val()));
            let out = linear_bf16(&host_values(x), &host_values(weight), bias.as_deref(), [b * n, d_in, d_out], unit);
            from_vec(out, [b, n, d_out], &device)
        }
        Plan::HostTraining(()) | Plan::Gpu(()) | Plan::Stock => linear.forward(x),
    }
}
