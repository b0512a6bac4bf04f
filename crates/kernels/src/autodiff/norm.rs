//! The instance norm (with its ReLU), the frozen batch norm's per-channel affine (with its ReLU),
//! the ReLU and the residual `relu(a + b)` with our backward: one node each in burn's autodiff
//! where burn records a chain of element-wise operations, forward and backward in parallel host
//! passes (`crate::host::norm_backward`).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, backend_extension};
use burn::tensor::{DType, Tensor};

use super::{dims4, flex, shape, values};
use crate::host::norm_backward::{
    InstanceNormSaved, add_relu_of, channel_affine_backward, channel_affine_forward, instance_norm_backward,
    instance_norm_forward, relu_backward, relu_of,
};

/// The norms whose backward is the host kernels'.
#[backend_extension(Flex, Autodiff)]
pub trait HostNormBackend: Backend {
    /// Instance norm of every `(n, c)` plane (biased variance, no affine), then a ReLU when `relu`.
    fn host_instance_norm(x: FloatTensor<Self>, epsilon: f64, relu: bool) -> FloatTensor<Self>;
    /// `max(0, a + b)`.
    fn host_add_relu(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self>;
    /// `max(0, x)`.
    fn host_relu(x: FloatTensor<Self>) -> FloatTensor<Self>;
    /// `x · scale[c] + shift[c]` per channel `c` (a frozen batch norm), then a ReLU when `relu`.
    fn host_channel_affine(
        x: FloatTensor<Self>,
        scale: FloatTensor<Self>,
        shift: FloatTensor<Self>,
        relu: bool,
    ) -> FloatTensor<Self>;
}

fn channel_affine_flex(x: &FlexTensor, scale: &FlexTensor, shift: &FlexTensor, relu: bool) -> FlexTensor {
    let dims = dims4(x);
    assert_eq!(shape(scale), [dims[1]], "channel affine: scale does not match the input's channels");
    flex(channel_affine_forward(&values(x), dims[2] * dims[3], &values(scale), &values(shift), relu), &dims)
}

fn instance_norm_forward_flex(x: &FlexTensor, epsilon: f64, relu: bool) -> (FlexTensor, InstanceNormSaved) {
    let dims = dims4(x);
    let (out, saved) = instance_norm_forward(&values(x), dims[2] * dims[3], epsilon, relu);
    (flex(out, &dims), saved)
}

fn relu_flex(x: &FlexTensor) -> FlexTensor {
    flex(relu_of(&values(x)), x.layout().shape())
}

fn add_relu_flex(a: &FlexTensor, b: &FlexTensor) -> FlexTensor {
    assert_eq!(dims4(a), dims4(b), "add_relu: shapes differ");
    flex(add_relu_of(&values(a), &values(b)), &dims4(a))
}

impl HostNormBackend for Flex {
    fn host_instance_norm(x: FlexTensor, epsilon: f64, relu: bool) -> FlexTensor {
        instance_norm_forward_flex(&x, epsilon, relu).0
    }

    fn host_add_relu(a: FlexTensor, b: FlexTensor) -> FlexTensor {
        add_relu_flex(&a, &b)
    }

    fn host_relu(x: FlexTensor) -> FlexTensor {
        relu_flex(&x)
    }

    fn host_channel_affine(x: FlexTensor, scale: FlexTensor, shift: FlexTensor, relu: bool) -> FlexTensor {
        channel_affine_flex(&x, &scale, &shift, relu)
    }
}

/// The backward node of [`HostNormBackend::host_relu`]; its state is the output.
#[derive(Debug)]
struct Relu;

impl Backward<Flex, 1> for Relu {
    type State = FlexTensor;

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        if let Some(node) = node_x {
            grads.register::<Flex>(node.id, flex(relu_backward(&values(&grad), &values(&ops.state)), &shape(&grad)));
        }
    }
}

/// The backward node of [`HostNormBackend::host_instance_norm`].
#[derive(Debug)]
struct InstanceNorm;

impl Backward<Flex, 1> for InstanceNorm {
    type State = (InstanceNormSaved, bool);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        if let Some(node) = node_x {
            let (saved, relu) = ops.state;
            let dx = instance_norm_backward(&values(&grad), &saved, relu);
            grads.register::<Flex>(node.id, flex(dx, &dims4(&grad)));
        }
    }
}

/// The backward node of [`HostNormBackend::host_add_relu`]: both inputs get the output gradient
/// where the output is positive.
#[derive(Debug)]
struct AddRelu;

impl Backward<Flex, 2> for AddRelu {
    type State = FlexTensor;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_a, node_b] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let dims = dims4(&grad);
        let masked = flex(relu_backward(&values(&grad), &values(&ops.state)), &dims);
        for node in [node_a, node_b].into_iter().flatten() {
            grads.register::<Flex>(node.id, masked.clone());
        }
    }
}

/// The backward node of [`HostNormBackend::host_channel_affine`]; its state is the input, the
/// scale and, with the ReLU, the output (its mask).
#[derive(Debug)]
struct ChannelAffine;

impl Backward<Flex, 3> for ChannelAffine {
    type State = (FlexTensor, FlexTensor, Option<FlexTensor>);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_scale, node_shift] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let dims = dims4(&grad);
        let (x, scale, y) = &ops.state;
        let y = y.as_ref().map(values);
        let (dx, dscale, dshift) =
            channel_affine_backward(&values(&grad), &values(x), y.as_deref(), dims[2] * dims[3], &values(scale));
        if let Some(node) = node_x {
            grads.register::<Flex>(node.id, flex(dx, &dims));
        }
        if let Some(node) = node_scale {
            grads.register::<Flex>(node.id, flex(dscale, &[dims[1]]));
        }
        if let Some(node) = node_shift {
            grads.register::<Flex>(node.id, flex(dshift, &[dims[1]]));
        }
    }
}

impl<C: CheckpointStrategy> HostNormBackend for Autodiff<Flex, C> {
    fn host_instance_norm(x: FloatTensor<Self>, epsilon: f64, relu: bool) -> FloatTensor<Self> {
        match InstanceNorm.prepare::<C>([x.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (out, saved) = instance_norm_forward_flex(x.primitive(), epsilon, relu);
                prep.finish((saved, relu), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(instance_norm_forward_flex(x.primitive(), epsilon, relu).0),
        }
    }

    fn host_add_relu(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        match AddRelu.prepare::<C>([a.node(), b.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = add_relu_flex(a.primitive(), b.primitive());
                prep.finish(out.clone(), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(add_relu_flex(a.primitive(), b.primitive())),
        }
    }

    fn host_channel_affine(
        x: FloatTensor<Self>,
        scale: FloatTensor<Self>,
        shift: FloatTensor<Self>,
        relu: bool,
    ) -> FloatTensor<Self> {
        let (xp, ap, bp) = (x.primitive(), scale.primitive(), shift.primitive());
        match ChannelAffine.prepare::<C>([x.node(), scale.node(), shift.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = channel_affine_flex(xp, ap, bp, relu);
                prep.finish((xp.clone(), ap.clone(), relu.then(|| out.clone())), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(channel_affine_flex(xp, ap, bp, relu)),
        }
    }

    fn host_relu(x: FloatTensor<Self>) -> FloatTensor<Self> {
        match Relu.prepare::<C>([x.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = relu_flex(x.primitive());
                prep.finish(out.clone(), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(relu_flex(x.primitive())),
        }
    }
}

/// Instance norm of every plane of `x` on the Flex autodiff device, float32 (biased variance, no
/// affine), then a ReLU when `relu`; its gradient from the host kernels.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output: the same
pub fn instance_norm(x: Tensor<4>, epsilon: f64, relu: bool) -> Tensor<4> {
    debug_assert_eq!(x.dtype(), DType::F32);
    let out = <burn::backend::Dispatch as HostNormBackend>::host_instance_norm(x.into_dispatch(), epsilon, relu);
    Tensor::from_dispatch(out)
}

/// `max(0, a + b)` on the Flex autodiff device, float32; its gradient from the host kernels.
///
/// # Shapes
/// - `a`, `b`: `[N, C, H, W]`, equal; output: the same
pub fn add_relu(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    debug_assert_eq!(a.dtype(), DType::F32);
    let out = <burn::backend::Dispatch as HostNormBackend>::host_add_relu(a.into_dispatch(), b.into_dispatch());
    Tensor::from_dispatch(out)
}

/// `max(0, x)` on the Flex autodiff device, float32; its gradient from the host kernels.
pub fn relu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    debug_assert_eq!(x.dtype(), DType::F32);
    Tensor::from_dispatch(<burn::backend::Dispatch as HostNormBackend>::host_relu(x.into_dispatch()))
}

/// `x · scale[c] + shift[c]` per channel `c` on the Flex autodiff device, float32 (a frozen batch
/// norm's affine), then a ReLU when `relu`; the gradients of `x`, `scale` and `shift` from the
/// host kernels.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `scale`, `shift`: `[C]`; output: as `x`
pub fn channel_affine(x: Tensor<4>, scale: Tensor<1>, shift: Tensor<1>, relu: bool) -> Tensor<4> {
    debug_assert_eq!(x.dtype(), DType::F32);
    let out = <burn::backend::Dispatch as HostNormBackend>::host_channel_affine(
        x.into_dispatch(),
        scale.into_dispatch(),
        shift.into_dispatch(),
        relu,
    );
    Tensor::from_dispatch(out)
}
