//! Per-channel normalisation with an optional ReLU in one parallel pass per plane, for CPU
//! inference.
//!
//! Design decision: burn's instance norm is six tensor operations (two means, a subtraction, a
//! square, a root and a division), a frozen batch norm two and the ReLU after either one more,
//! each a full pass over the activation on one thread of burn Flex. In the feature encoder's
//! full-resolution layers (2 images x 64 channels x 192 x 224 at 384x448) that is most of the
//! time outside the convolutions. Here each `(image, channel)` plane is one rayon task: its
//! statistics in `f64`, then normalisation, affine and ReLU in the same pass. Only for plain CPU
//! tensors without autodiff (the dispatch's host path, `crate::ops::norm`); the tensor operations
//! stay the reference and the path for training and the GPU, and the tests check both agree.

use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;

use dgstereo_core::tensor::to_vec;

/// What [`normalize_planes`] does to each plane before the optional ReLU.
#[derive(Debug, Clone)]
pub enum PlaneNorm {
    /// Instance norm: subtract the plane's mean, divide by `sqrt(var + epsilon)` (biased
    /// variance), no affine.
    Instance {
        /// Added to the variance.
        epsilon: f64,
    },
    /// `x * scale[c] + shift[c]` (a frozen batch norm folded to one affine per channel).
    Affine {
        /// Per-channel factor.
        scale: Vec<f32>,
        /// Per-channel offset.
        shift: Vec<f32>,
    },
    /// Nothing (only the ReLU, if asked).
    Identity,
}

/// `norm` applied to every `(n, c)` plane of `x`, then `max(0, ·)` when `relu`.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output: the same
///
/// # Panics
/// When an affine norm's `scale` or `shift` does not have `C` entries.
pub fn normalize_planes(x: Tensor<4>, norm: &PlaneNorm, relu: bool) -> Tensor<4> {
    let device = x.device();
    let dims = x.dims();
    let [_, c, h, w] = dims;
    if let PlaneNorm::Affine { scale, shift } = norm {
        assert!(
            scale.len() == c && shift.len() == c,
            "affine norm of {} / {} entries for {c} channels",
            scale.len(),
            shift.len()
        );
    }
    let plane = h * w;
    let mut values = to_vec(x);
    values.par_chunks_mut(plane.max(1)).enumerate().for_each(|(i, p)| {
        let (a, b) = match norm {
            &PlaneNorm::Instance { epsilon } => {
                let mean = lane_sum(p, |v| v) / plane as f64;
                let var = lane_sum(p, |v| (v - mean) * (v - mean)) / plane as f64;
                let inv = 1.0 / (var + epsilon).sqrt();
                (inv as f32, (-mean * inv) as f32)
            }
            PlaneNorm::Affine { scale, shift } => (scale[i % c], shift[i % c]),
            PlaneNorm::Identity => (1.0, 0.0),
        };
        if relu {
            p.iter_mut().for_each(|v| *v = (*v * a + b).max(0.0));
        } else {
            p.iter_mut().for_each(|v| *v = *v * a + b);
        }
    });
    Tensor::from_data(TensorData::new(values, dims), &device)
}

/// Independent partial sums: a plane's statistics as one running `f64` sum were a chain of
/// dependent additions (one per value, each waiting for the last): 39-60 ms for the stem's
/// instance norm of two 384x448 images on the Xeon, half as long as the convolution before it;
/// 15-18 ms in eight lanes.
const LANES: usize = 8;

/// `Σ f(v as f64)` over `values`, in [`LANES`] independent partial sums (added in order at the
/// end) so the additions overlap and vectorise.
#[inline(always)]
pub(crate) fn lane_sum(values: &[f32], f: impl Fn(f64) -> f64) -> f64 {
    let mut lanes = [0.0f64; LANES];
    let (chunks, tail) = values.as_chunks::<LANES>();
    for chunk in chunks {
        for j in 0..LANES {
            lanes[j] += f(chunk[j] as f64);
        }
    }
    lanes.iter().sum::<f64>() + tail.iter().map(|&v| f(v as f64)).sum::<f64>()
}

/// `max(0, a + b)` in one parallel host pass.
///
/// # Shapes
/// - `a`, `b`: `[N, C, H, W]`, equal; output: the same
///
/// # Panics
/// When the shapes differ.
pub fn add_relu(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    let device = a.device();
    let dims = a.dims();
    assert_eq!(dims, b.dims(), "add_relu: shapes differ");
    let mut values = to_vec(a);
    let other = to_vec(b);
    const CHUNK: usize = 1 << 14;
    values.par_chunks_mut(CHUNK).zip(other.par_chunks(CHUNK)).for_each(|(v, o)| {
        v.iter_mut().zip(o).for_each(|(v, o)| *v = (*v + o).max(0.0));
    });
    Tensor::from_data(TensorData::new(values, dims), &device)
}

#[cfg(test)]
mod tests {
    use burn::tensor::activation::relu;
    use burn::tensor::{Device, Distribution};

    use super::*;
    use dgstereo_core::tensor::{instance_norm, max_abs_diff};

    fn random(dims: [usize; 4]) -> Tensor<4> {
        Tensor::random(dims, Distribution::Normal(0.5, 2.0), &Device::flex())
    }

    #[test]
    fn planes_agree_with_the_tensor_operations() {
        let x = random([2, 5, 7, 9]);
        for relu_after in [false, true] {
            let stock = instance_norm(x.clone(), 1e-5);
            let stock = if relu_after { relu(stock) } else { stock };
            let host = normalize_planes(x.clone(), &PlaneNorm::Instance { epsilon: 1e-5 }, relu_after);
            assert!(max_abs_diff(stock, host) < 1e-5);
        }
        let scale = [0.5, -1.0, 2.0, 0.0, 1.5];
        let shift = [0.1, 0.2, -0.3, 0.4, 0.0];
        let s = Tensor::<1>::from_floats(scale, &Device::flex()).reshape([1, 5, 1, 1]);
        let t = Tensor::<1>::from_floats(shift, &Device::flex()).reshape([1, 5, 1, 1]);
        let stock = relu(x.clone() * s + t);
        let host =
            normalize_planes(x.clone(), &PlaneNorm::Affine { scale: scale.to_vec(), shift: shift.to_vec() }, true);
        assert!(max_abs_diff(stock, host) < 1e-6);
        assert!(max_abs_diff(relu(x.clone()), normalize_planes(x, &PlaneNorm::Identity, true)) == 0.0);
    }

    #[test]
    fn add_relu_agrees_with_the_tensor_operations() {
        let (a, b) = (random([1, 3, 70, 300]), random([1, 3, 70, 300]));
        let expected = relu(a.clone() + b.clone());
        assert!(max_abs_diff(expected, add_relu(a, b)) == 0.0);
    }

    #[test]
    #[should_panic(expected = "affine norm of 2 / 2 entries for 5 channels")]
    fn an_affine_norm_of_the_wrong_width_is_refused() {
        normalize_planes(
            random([1, 5, 2, 2]),
            &PlaneNorm::Affine { scale: vec![1.0, 1.0], shift: vec![0.0, 0.0] },
            false,
        );
    }
}
