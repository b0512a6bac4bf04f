//! Small conversions between tensors and plain vectors.

use burn::tensor::{Device, Tensor, TensorData};

/// A tensor's values as a flat `Vec<f32>` in row-major order.
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    // `try_into_vec` takes the buffer over when the tensor owned it alone (no copy), where
    // `try_to_vec` would always copy it.
    t.into_data().convert::<f32>().try_into_vec::<f32>().expect("float tensor data")
}

/// A float tensor of `shape` from row-major `values`.
///
/// # Panics
/// When `values.len()` is not the product of `shape`.
pub fn from_vec<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// The largest absolute difference between two tensors of the same shape.
pub fn max_abs_diff<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
    let a = to_vec(a);
    let b = to_vec(b);
    a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// Instance normalisation of `[N, C, H, W]` over `H, W` (biased variance, no affine).
pub fn instance_norm(x: Tensor<4>, epsilon: f64) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let flat = x.reshape([n, c, h * w]);
    let mean = flat.clone().mean_dim(2);
    let centred = flat - mean;
    let var = centred.clone().square().mean_dim(2);
    (centred / var.add_scalar(epsilon).sqrt()).reshape([n, c, h, w])
}
