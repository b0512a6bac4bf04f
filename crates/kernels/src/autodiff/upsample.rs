//! Convex upsampling with our backward: the forward runs the host pass on the inner Flex
//! tensors and registers a node whose backward computes the gradients of the flow and the mask
//! ([`crate::host::upsample_backward`]).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, backend_extension};
use burn::tensor::{DType, Tensor};

use super::{dims4, flex, values};
use crate::host::upsample::convex_upsample_values;
use crate::host::upsample_backward::convex_upsample_backward;

/// Convex upsampling whose backward is the host kernels'.
#[backend_extension(Flex, Autodiff)]
pub trait HostUpsampleBackend: Backend {
    /// `flow` `[N, D, H, W]` upsampled by `factor` with the weights of `mask` `[N, 9·factor², H,
    /// W]` (`crate::ops::upsample::convex_upsample`).
    fn host_convex_upsample(flow: FloatTensor<Self>, mask: FloatTensor<Self>, factor: usize) -> FloatTensor<Self>;
}

fn forward(flow: &FlexTensor, mask: &FlexTensor, factor: usize) -> FlexTensor {
    let [n, d, h, w] = dims4(flow);
    let out = convex_upsample_values(&values(flow), &values(mask), [n, d, h, w], factor);
    flex(out, &[n, d, factor * h, factor * w])
}

impl HostUpsampleBackend for Flex {
    fn host_convex_upsample(flow: FlexTensor, mask: FlexTensor, factor: usize) -> FlexTensor {
        forward(&flow, &mask, factor)
    }
}

/// The backward node of [`HostUpsampleBackend::host_convex_upsample`]; its state is the flow,
/// the mask and the factor.
#[derive(Debug)]
struct ConvexUpsample;

impl Backward<Flex, 2> for ConvexUpsample {
    type State = (FlexTensor, FlexTensor, usize);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_flow, node_mask] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let (flow, mask, factor) = &ops.state;
        let dims = dims4(flow);
        let (dflow, dmask) = convex_upsample_backward(&values(flow), &values(mask), &values(&grad), dims, *factor);
        if let Some(node) = node_flow {
            grads.register::<Flex>(node.id, flex(dflow, &dims));
        }
        if let Some(node) = node_mask {
            grads.register::<Flex>(node.id, flex(dmask, &dims4(mask)));
        }
    }
}

impl<C: CheckpointStrategy> HostUpsampleBackend for Autodiff<Flex, C> {
    fn host_convex_upsample(flow: FloatTensor<Self>, mask: FloatTensor<Self>, factor: usize) -> FloatTensor<Self> {
        let (fp, mp) = (flow.primitive(), mask.primitive());
        match ConvexUpsample.prepare::<C>([flow.node(), mask.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = forward(fp, mp, factor);
                prep.finish((fp.clone(), mp.clone(), factor), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(forward(fp, mp, factor)),
        }
    }
}

/// Convex upsampling on the Flex autodiff device, float32; its gradients from the host kernels.
///
/// # Shapes
/// - `flow`: `[N, D, H, W]`, `mask`: `[N, 9·factor², H, W]`; output `[N, D, factor·H, factor·W]`
pub fn convex_upsample(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    debug_assert_eq!(flow.dtype(), DType::F32);
    Tensor::from_dispatch(<burn::backend::Dispatch as HostUpsampleBackend>::host_convex_upsample(
        flow.into_dispatch(),
        mask.into_dispatch(),
        factor,
    ))
}
