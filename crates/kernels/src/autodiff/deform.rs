//! DGIA's deformable convolution with our backward: the forward runs the host kernel on the inner
//! Flex tensors and registers a node whose backward computes the gradients of the input, the
//! offsets, the weight and the bias on host buffers (`crate::host::deform_backward`).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, backend_extension};
use burn::tensor::{DType, Tensor};

use super::{dims4, flex, values};
pub use crate::host::deform::DeformOptions;
use crate::host::deform::{Geometry, deform_slices};
use crate::host::deform_backward::deform_backward;

/// The deformable convolution whose backward is the host kernels'.
#[backend_extension(Flex, Autodiff)]
pub trait HostDeformBackend: Backend {
    /// `deform_conv2d(x, offset, weight, bias)` with `options`, without a mask.
    fn host_deform_conv2d(
        x: FloatTensor<Self>,
        offset: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: DeformOptions,
    ) -> FloatTensor<Self>;
}

fn geometry(x: &FlexTensor, weight: &FlexTensor, options: DeformOptions) -> Geometry {
    Geometry::new(dims4(x), dims4(weight), options)
        .expect("deformable convolution: the kernel does not fit the padded input")
}

fn forward(
    x: &FlexTensor,
    offset: &FlexTensor,
    weight: &FlexTensor,
    bias: &FlexTensor,
    options: DeformOptions,
) -> FlexTensor {
    let g = geometry(x, weight, options);
    let n = dims4(x)[0];
    assert_eq!(
        dims4(offset),
        [n, 2 * g.kh * g.kw, g.out_h, g.out_w],
        "deformable convolution: offsets must be [N, 2·kh·kw, H_out, W_out]"
    );
    let out = deform_slices(&values(x), n, &values(offset), &values(weight), Some(&values(bias)), g);
    flex(out, &[n, g.o, g.out_h, g.out_w])
}

impl HostDeformBackend for Flex {
    fn host_deform_conv2d(
        x: FlexTensor,
        offset: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        options: DeformOptions,
    ) -> FlexTensor {
        forward(&x, &offset, &weight, &bias, options)
    }
}

/// The backward node of [`HostDeformBackend::host_deform_conv2d`]; its state is the input, the
/// offsets, the weight and the options.
#[derive(Debug)]
struct HostDeform;

impl Backward<Flex, 4> for HostDeform {
    type State = (FlexTensor, FlexTensor, FlexTensor, DeformOptions);

    fn backward(self, ops: Ops<Self::State, 4>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_offset, node_weight, node_bias] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let (x, offset, weight, options) = ops.state;
        let g = geometry(&x, &weight, options);
        let n = dims4(&x)[0];
        let d = deform_backward(&values(&x), n, &values(&offset), &values(&weight), &values(&grad), g);
        let registered = [
            (node_x, d.input, dims4(&x).to_vec()),
            (node_offset, d.offset, dims4(&offset).to_vec()),
            (node_weight, d.weight, dims4(&weight).to_vec()),
            (node_bias, d.bias, vec![g.o]),
        ];
        for (node, values, dims) in registered {
            if let Some(node) = node {
                grads.register::<Flex>(node.id, flex(values, &dims));
            }
        }
    }
}

impl<C: CheckpointStrategy> HostDeformBackend for Autodiff<Flex, C> {
    fn host_deform_conv2d(
        x: FloatTensor<Self>,
        offset: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: DeformOptions,
    ) -> FloatTensor<Self> {
        let parents = [x.node(), offset.node(), weight.node(), bias.node()];
        match HostDeform.prepare::<C>(parents).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = forward(x.primitive(), offset.primitive(), weight.primitive(), bias.primitive(), options);
                let state = (x.primitive().clone(), offset.primitive().clone(), weight.primitive().clone(), options);
                prep.finish(state, out)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(forward(x.primitive(), offset.primitive(), weight.primitive(), bias.primitive(), options))
            }
        }
    }
}

/// `deform_conv2d(x, offset, weight, bias)` with `options` on the Flex autodiff device, float32,
/// without a mask; its gradients from the host kernels; `bias` zeros where the convolution has
/// none (a constant, so no gradient is computed for it).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `offset`: `[N, 2·kh·kw, H_out, W_out]`; `weight`: `[O, C, kh, kw]`;
///   `bias`: `[O]`; output `[N, O, H_out, W_out]`
pub fn deform_conv2d(
    x: Tensor<4>,
    offset: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: DeformOptions,
) -> Tensor<4> {
    debug_assert_eq!(x.dtype(), DType::F32);
    let bias = bias.unwrap_or_else(|| Tensor::zeros([weight.dims()[0]], &x.device()));
    let out = <burn::backend::Dispatch as HostDeformBackend>::host_deform_conv2d(
        x.into_dispatch(),
        offset.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        options,
    );
    Tensor::from_dispatch(out)
}
