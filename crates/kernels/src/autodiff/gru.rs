//! The ConvGRU step's gates `σ(a + b)` and blend `(1 − z)·h + z·tanh(q + c)` with our backward:
//! one node each in burn's autodiff, forward and backward in parallel host passes
//! (`crate::host::gru_backward`). The step's convolutions are [`super::conv`]'s.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, backend_extension};
use burn::tensor::{DType, Tensor};

use super::{flex, shape, values};
use crate::host::gru_backward::{blend_backward, blend_forward, gates_backward, gates_forward};

/// The GRU step's element-wise parts whose backward is the host kernels'.
#[backend_extension(Flex, Autodiff)]
pub trait HostGruBackend: Backend {
    /// `σ(a + b)`, `a` and `b` of one shape.
    fn host_gru_gates(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self>;
    /// `(1 − z)·h + z·tanh(q + c)`, all of one shape.
    fn host_gru_blend(
        q: FloatTensor<Self>,
        c: FloatTensor<Self>,
        z: FloatTensor<Self>,
        h: FloatTensor<Self>,
    ) -> FloatTensor<Self>;
}

fn same_shapes(tensors: &[&FlexTensor]) -> Vec<usize> {
    let dims = shape(tensors[0]);
    assert!(tensors.iter().all(|t| shape(t) == dims), "GRU element-wise part: shapes differ");
    dims
}

fn gates_flex(a: &FlexTensor, b: &FlexTensor) -> FlexTensor {
    let dims = same_shapes(&[a, b]);
    flex(gates_forward(&values(a), &values(b)), &dims)
}

/// The blend's output and its `tanh(q + c)`.
fn blend_flex(q: &FlexTensor, c: &FlexTensor, z: &FlexTensor, h: &FlexTensor) -> (FlexTensor, FlexTensor) {
    let dims = same_shapes(&[q, c, z, h]);
    let (out, t) = blend_forward(&values(q), &values(c), &values(z), &values(h));
    (flex(out, &dims), flex(t, &dims))
}

impl HostGruBackend for Flex {
    fn host_gru_gates(a: FlexTensor, b: FlexTensor) -> FlexTensor {
        gates_flex(&a, &b)
    }

    fn host_gru_blend(q: FlexTensor, c: FlexTensor, z: FlexTensor, h: FlexTensor) -> FlexTensor {
        blend_flex(&q, &c, &z, &h).0
    }
}

/// The backward node of [`HostGruBackend::host_gru_gates`]: both inputs get `g·s·(1 − s)`.
#[derive(Debug)]
struct Gates;

impl Backward<Flex, 2> for Gates {
    type State = FlexTensor;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_a, node_b] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let d = flex(gates_backward(&values(&grad), &values(&ops.state)), &shape(&grad));
        for node in [node_a, node_b].into_iter().flatten() {
            grads.register::<Flex>(node.id, d.clone());
        }
    }
}

/// The backward node of [`HostGruBackend::host_gru_blend`]; its state is `(tanh(q + c), z, h)`.
#[derive(Debug)]
struct Blend;

impl Backward<Flex, 4> for Blend {
    type State = (FlexTensor, FlexTensor, FlexTensor);

    fn backward(self, ops: Ops<Self::State, 4>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_q, node_c, node_z, node_h] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let dims = shape(&grad);
        let (t, z, h) = &ops.state;
        let [dq, dz, dh] = blend_backward(&values(&grad), &values(t), &values(z), &values(h));
        let dq = flex(dq, &dims);
        for node in [node_q, node_c].into_iter().flatten() {
            grads.register::<Flex>(node.id, dq.clone());
        }
        if let Some(node) = node_z {
            grads.register::<Flex>(node.id, flex(dz, &dims));
        }
        if let Some(node) = node_h {
            grads.register::<Flex>(node.id, flex(dh, &dims));
        }
    }
}

impl<C: CheckpointStrategy> HostGruBackend for Autodiff<Flex, C> {
    fn host_gru_gates(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        match Gates.prepare::<C>([a.node(), b.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = gates_flex(a.primitive(), b.primitive());
                prep.finish(out.clone(), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(gates_flex(a.primitive(), b.primitive())),
        }
    }

    fn host_gru_blend(
        q: FloatTensor<Self>,
        c: FloatTensor<Self>,
        z: FloatTensor<Self>,
        h: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        let (qp, cp, zp, hp) = (q.primitive(), c.primitive(), z.primitive(), h.primitive());
        match Blend.prepare::<C>([q.node(), c.node(), z.node(), h.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (out, t) = blend_flex(qp, cp, zp, hp);
                prep.finish((t, zp.clone(), hp.clone()), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(blend_flex(qp, cp, zp, hp).0),
        }
    }
}

/// `σ(a + b)` on the Flex autodiff device, float32; its gradient from the host kernels.
pub fn gates<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> Tensor<D> {
    debug_assert_eq!(a.dtype(), DType::F32);
    Tensor::from_dispatch(<burn::backend::Dispatch as HostGruBackend>::host_gru_gates(
        a.into_dispatch(),
        b.into_dispatch(),
    ))
}

/// `(1 − z)·h + z·tanh(q + c)` on the Flex autodiff device, float32; its gradients from the host
/// kernels.
pub fn blend<const D: usize>(q: Tensor<D>, c: Tensor<D>, z: Tensor<D>, h: Tensor<D>) -> Tensor<D> {
    debug_assert_eq!(q.dtype(), DType::F32);
    Tensor::from_dispatch(<burn::backend::Dispatch as HostGruBackend>::host_gru_blend(
        q.into_dispatch(),
        c.into_dispatch(),
        z.into_dispatch(),
        h.into_dispatch(),
    ))
}
