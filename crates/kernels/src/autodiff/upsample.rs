//! Convex upsampling with our backward: the forward runs the host pass on the inner Flex
//! tensors, keeping its softmax weights, and registers a node whose backward computes the
//! gradients of the flow and the mask from them (`crate::host::upsample_backward`).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, backend_extension};
use burn::tensor::{DType, Tensor};

use super::{dims4, flex, values};
use crate::host::upsample::{convex_upsample_values, convex_upsample_values_keeping_weights};
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

/// The backward node of [`HostUpsampleBackend::host_convex_upsample`].
#[derive(Debug)]
struct ConvexUpsample;

/// What the backward reads: the flow, the forward's softmax weights (`[N][H][W][factor²][9]`, as
/// large as the mask, which the node then does not keep), the mask's shape and the factor.
#[derive(Debug, Clone)]
struct UpsampleState {
    flow: FlexTensor,
    weights: Vec<f32>,
    mask_dims: [usize; 4],
    factor: usize,
}

impl Backward<Flex, 2> for ConvexUpsample {
    type State = UpsampleState;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_flow, node_mask] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let UpsampleState { flow, weights, mask_dims, factor } = &ops.state;
        let dims = dims4(flow);
        let (dflow, dmask) = convex_upsample_backward(&values(flow), weights, &values(&grad), dims, *factor);
        if let Some(node) = node_flow {
            grads.register::<Flex>(node.id, flex(dflow, &dims));
        }
        if let Some(node) = node_mask {
            grads.register::<Flex>(node.id, flex(dmask, mask_dims));
        }
    }
}

impl<C: CheckpointStrategy> HostUpsampleBackend for Autodiff<Flex, C> {
    fn host_convex_upsample(flow: FloatTensor<Self>, mask: FloatTensor<Self>, factor: usize) -> FloatTensor<Self> {
        let (fp, mp) = (flow.primitive(), mask.primitive());
        match ConvexUpsample.prepare::<C>([flow.node(), mask.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let [n, d, h, w] = dims4(fp);
                let (out, weights) =
                    convex_upsample_values_keeping_weights(&values(fp), &values(mp), [n, d, h, w], factor);
                let state = UpsampleState { flow: fp.clone(), weights, mask_dims: dims4(mp), factor };
                prep.finish(state, flex(out, &[n, d, factor * h, factor * w]))
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
