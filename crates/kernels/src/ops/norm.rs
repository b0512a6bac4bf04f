//! Per-channel norms with an optional ReLU, and the residual `relu(a + b)`: one parallel host
//! pass per plane for CPU inference ([`crate::host::norm`]), burn's operations elsewhere.

use burn::tensor::Tensor;
use burn::tensor::activation::relu;

use crate::dispatch::{Op, Path, path};
use crate::host::norm;
pub use crate::host::norm::PlaneNorm;

/// `norm()` applied to every `(n, c)` plane of `x`, then `max(0, ·)` when `relu`, where the
/// dispatch takes the host pass (`norm` is called only there); `stock(x)` (burn's norm module and
/// ReLU, the reference) elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output: the same
pub fn normalize_planes_or(
    x: Tensor<4>,
    norm: impl FnOnce() -> PlaneNorm,
    relu: bool,
    stock: impl FnOnce(Tensor<4>) -> Tensor<4>,
) -> Tensor<4> {
    match path(&x.device(), Op::Norm) {
        Path::Host => norm::normalize_planes(x, &norm(), relu),
        Path::Gpu | Path::Stock => stock(x),
    }
}

/// `max(0, a + b)`: one parallel host pass for CPU inference, burn's operations elsewhere.
///
/// # Shapes
/// - `a`, `b`: `[N, C, H, W]`, equal; output: the same
pub fn add_relu(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    match path(&a.device(), Op::Norm) {
        Path::Host => norm::add_relu(a, b),
        Path::Gpu | Path::Stock => relu(a + b),
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::{instance_norm, max_abs_diff};

    use super::*;
    use crate::dispatch::with_path;

    fn operands() -> [Tensor<4>; 2] {
        let device = Device::flex();
        [Distribution::Normal(0.5, 2.0), Distribution::Normal(0.0, 1.0)]
            .map(|d| Tensor::<4>::random([2, 3, 9, 11], d, &device))
    }

    crate::test_paths!(
        /// Every path gives burn's result.
        fn every_path_agrees_with_the_tensor_operations(pinned) {
            let [x, b] = operands();
            let expected = relu(instance_norm(x.clone(), 1e-5));
            let got = normalize_planes_or(x.clone(), || PlaneNorm::Instance { epsilon: 1e-5 }, true, |x| {
                relu(instance_norm(x, 1e-5))
            });
            assert!(max_abs_diff(expected, got) < 1e-5, "{pinned:?}");
            assert!(max_abs_diff(relu(x.clone() + b.clone()), add_relu(x, b)) < 1e-6, "{pinned:?}");
        }
    );

    /// Under autodiff burn's operations run even where the host path is pinned.
    #[test]
    fn autodiff_keeps_the_tensor_operations() {
        let [x, b] = operands();
        let expected = relu(x.clone() + b.clone());
        let ad = Device::flex().autodiff();
        let [xa, ba] = [x, b].map(|t| Tensor::<4>::from_data(t.into_data(), &ad));
        let stock = with_path(Path::Host, || add_relu(xa, ba));
        assert!(max_abs_diff(expected, Tensor::from_data(stock.into_data(), &Device::flex())) == 0.0);
    }
}
