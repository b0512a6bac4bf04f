//! Operations whose backward pass is ours: burn's autodiff records each as one node, and its
//! gradients come from host kernels.
//!
//! Design decision: burn lets an operation define its own backward through a backend extension
//! (`#[backend_extension]`) implemented for `Autodiff<Flex>`: the forward runs a host kernel on
//! the inner Flex tensors and registers a node whose backward computes the gradients on host
//! buffers, in parallel where burn's element-wise operations run on one thread. burn's own
//! autodiff of the same operations stays the reference the tests compare with, and the path the
//! settings' `stock-training` restores. [`conv`]: the convolution; [`deform`]: DGIA's deformable
//! convolution; [`norm`]: the instance norm
//! with its ReLU and the residual `relu(a + b)`; [`gru`]: the ConvGRU step's gates and blend;
//! [`upsample`]: convex upsampling.

use burn::backend::flex::FlexTensor;
use burn::tensor::TensorData;

pub(crate) mod conv;
pub(crate) mod deform;
pub(crate) mod gru;
pub(crate) mod norm;
pub(crate) mod upsample;

/// A float32 Flex tensor's values, row-major (a copy only where it is not contiguous).
fn values(t: &FlexTensor) -> std::borrow::Cow<'_, [f32]> {
    match t.as_slice::<f32>() {
        Some(v) if t.is_contiguous() => std::borrow::Cow::Borrowed(v),
        _ => std::borrow::Cow::Owned(t.to_contiguous().as_slice::<f32>().expect("a float32 tensor").to_vec()),
    }
}

fn dims4(t: &FlexTensor) -> [usize; 4] {
    let shape = t.layout().shape();
    [shape[0], shape[1], shape[2], shape[3]]
}

/// A Flex tensor's shape, any rank.
fn shape(t: &FlexTensor) -> Vec<usize> {
    t.layout().shape().to_vec()
}

fn flex(values: Vec<f32>, dims: &[usize]) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, dims.to_vec()))
}
