//! Per-channel norms with an optional ReLU, and the residual `relu(a + b)`: one parallel host
//! pass per plane for CPU inference (`crate::host::norm`); in training the instance norm, the
//! frozen batch norm's affine, the ReLU and `relu(a + b)` are nodes with our backward
//! (`crate::autodiff::norm`); burn's operations, the reference, elsewhere.

use burn::tensor::Tensor;
use burn::tensor::activation::relu;
use dgstereo_core::tensor::{instance_norm, to_vec};

use crate::autodiff;
use crate::dispatch::{ADD_RELU, NormCall, NormKind, Plan, RECTIFY, plan};
use crate::host::norm::{self, PlaneNorm};

/// A norm over each `(n, c)` plane that [`normalize_planes`] applies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Normalization {
    /// Instance norm: subtract the plane's mean, divide by `sqrt(var + epsilon)` (biased
    /// variance), no affine (PyTorch's `InstanceNorm2d` default).
    Instance {
        /// Added to the variance.
        epsilon: f64,
    },
    /// Nothing (only the ReLU, if asked).
    Identity,
}

/// `norm` applied to every `(n, c)` plane of `x`, then `max(0, ·)` when `relu`.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output: the same
pub fn normalize_planes(x: Tensor<4>, norm: Normalization, relu: bool) -> Tensor<4> {
    let kind = match norm {
        Normalization::Instance { .. } => NormKind::Instance,
        Normalization::Identity => NormKind::Identity,
    };
    match plan(&x.device(), &NormCall { kind, relu }) {
        Plan::HostInference(()) => {
            let host = match norm {
                Normalization::Instance { epsilon } => PlaneNorm::Instance { epsilon },
                Normalization::Identity => PlaneNorm::Identity,
            };
            norm::normalize_planes(x, &host, relu)
        }
        Plan::HostTraining(()) => match norm {
            Normalization::Instance { epsilon } => autodiff::norm::instance_norm(x, epsilon, relu),
            Normalization::Identity => autodiff::norm::relu(x),
        },
        Plan::Gpu(()) | Plan::Stock => {
            let y = match norm {
                Normalization::Instance { epsilon } => instance_norm(x, epsilon),
                Normalization::Identity => x,
            };
            if relu { rectify(y) } else { y }
        }
    }
}

/// A frozen batch norm, `x · scale[c] + shift[c]` per channel `c`, then `max(0, ·)` when
/// `relu`: in training one node with our backward (the gradients reach `scale` and `shift`, and
/// through them the norm's parameters), for CPU inference the host pass, burn's operations
/// elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `scale`, `shift`: `[C]`; output: as `x`
pub fn affine_planes(x: Tensor<4>, scale: Tensor<1>, shift: Tensor<1>, relu: bool) -> Tensor<4> {
    match plan(&x.device(), &NormCall { kind: NormKind::AffineTensors, relu }) {
        Plan::HostTraining(()) => autodiff::norm::channel_affine(x, scale, shift, relu),
        Plan::HostInference(()) => {
            norm::normalize_planes(x, &PlaneNorm::Affine { scale: to_vec(scale), shift: to_vec(shift) }, relu)
        }
        Plan::Gpu(()) | Plan::Stock => {
            let c = scale.dims()[0];
            let y = x * scale.reshape([1, c, 1, 1]) + shift.reshape([1, c, 1, 1]);
            if relu { rectify(y) } else { y }
        }
    }
}

/// `max(0, x)`: in training one node with our backward, burn's ReLU elsewhere (CPU inference
/// folds its ReLUs into the kernels before).
pub fn rectify<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    match plan(&x.device(), &RECTIFY) {
        Plan::HostTraining(()) => autodiff::norm::relu(x),
        Plan::HostInference(()) | Plan::Gpu(()) | Plan::Stock => relu(x),
    }
}

/// `max(0, a + b)`: one parallel host pass for CPU inference, a node with our backward in
/// training, burn's operations elsewhere.
///
/// # Shapes
/// - `a`, `b`: `[N, C, H, W]`, equal; output: the same
pub fn add_relu(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    match plan(&a.device(), &ADD_RELU) {
        Plan::HostTraining(()) => autodiff::norm::add_relu(a, b),
        Plan::HostInference(()) => norm::add_relu(a, b),
        Plan::Gpu(()) | Plan::Stock => relu(a + b),
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::max_abs_diff;

    use super::*;
    use crate::dispatch::{Path, with_path};

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
            let got = normalize_planes(x.clone(), Normalization::Instance { epsilon: 1e-5 }, true);
            assert!(max_abs_diff(expected, got) < 1e-5, "{pinned:?}");
            assert!(max_abs_diff(relu(x.clone() + b.clone()), add_relu(x, b)) < 1e-6, "{pinned:?}");
        }
    );

    /// Under autodiff the instance norm (with and without its ReLU), the ReLU and `relu(a + b)` give burn's
    /// values and gradients: the loss `Σ y·r` with a random `r`, the gradients of every input.
    #[test]
    fn training_nodes_agree_with_burns_autodiff() {
        let ad = Device::flex().autodiff();
        let [x, b] = operands().map(|t| Tensor::<4>::from_data(t.into_data(), &ad));
        let r = Tensor::<4>::random(x.dims(), Distribution::Normal(0.0, 1.0), &ad);
        let plain = |t: Tensor<4>| Tensor::<4>::from_data(t.into_data(), &Device::flex());
        let run = |pinned: Path, relu_after: bool| {
            let (x, b) = (x.clone().detach().require_grad(), b.clone().detach().require_grad());
            let norm = with_path(pinned, || {
                normalize_planes(x.clone(), Normalization::Instance { epsilon: 1e-5 }, relu_after)
            });
            let sum = with_path(pinned, || add_relu(norm.clone(), b.clone()));
            let rectified = with_path(pinned, || rectify(b.clone().add_scalar(0.3)));
            let grads = ((norm.clone() * r.clone()).sum()
                + (sum.clone() * r.clone()).sum()
                + (rectified.clone() * r.clone()).sum())
            .backward();
            let gx = x.grad(&grads).expect("the input's gradient");
            let gb = b.grad(&grads).expect("the residual's gradient");
            [norm, sum, rectified, gx, gb].map(|t| plain(t.detach()))
        };
        for relu_after in [true, false] {
            let [norm0, sum0, rect0, gx0, gb0] = run(Path::Stock, relu_after);
            let [norm1, sum1, rect1, gx1, gb1] = run(Path::Host, relu_after);
            assert!(max_abs_diff(norm0, norm1) < 1e-5, "relu {relu_after}: norm");
            assert!(max_abs_diff(sum0, sum1) < 1e-5, "relu {relu_after}: add_relu");
            assert!(max_abs_diff(rect0, rect1) == 0.0, "relu {relu_after}: rectify");
            let scale = to_vec(gx0.clone()).iter().fold(1e-6f32, |m, v| m.max(v.abs()));
            assert!(max_abs_diff(gx0, gx1) < 1e-4 * scale, "relu {relu_after}: input gradient");
            assert!(max_abs_diff(gb0, gb1) == 0.0, "relu {relu_after}: residual gradient");
        }
    }

    /// Under autodiff the frozen batch norm's affine (with and without its ReLU) gives burn's
    /// values and the gradients of the input, the scale and the shift (the loss `Σ y·r`, a random
    /// `r`; scale and shift derived from parameters as the encoder derives them), at batch 2.
    #[test]
    fn the_affine_node_agrees_with_burns_autodiff() {
        let ad = Device::flex().autodiff();
        let [x, _] = operands().map(|t| Tensor::<4>::from_data(t.into_data(), &ad));
        let c = x.dims()[1];
        let r = Tensor::<4>::random(x.dims(), Distribution::Normal(0.0, 1.0), &ad);
        let (weight, bias) = (
            Tensor::<1>::random([c], Distribution::Normal(1.0, 0.5), &ad),
            Tensor::<1>::random([c], Distribution::Normal(0.0, 0.5), &ad),
        );
        let plain = |t: Tensor<4>| Tensor::<4>::from_data(t.into_data(), &Device::flex());
        let run = |pinned: Path, relu_after: bool| {
            let (x, w, b) = (
                x.clone().detach().require_grad(),
                weight.clone().detach().require_grad(),
                bias.clone().detach().require_grad(),
            );
            let (scale, shift) = (w.clone().mul_scalar(0.7), b.clone() - w.clone().mul_scalar(0.2));
            let y = with_path(pinned, || affine_planes(x.clone(), scale, shift, relu_after));
            let grads = (y.clone() * r.clone()).sum().backward();
            let gx = x.grad(&grads).expect("the input's gradient");
            let (gw, gb) =
                (w.grad(&grads).expect("the weight's gradient"), b.grad(&grads).expect("the bias's gradient"));
            (plain(y.detach()), plain(gx), to_vec(gw), to_vec(gb))
        };
        for relu_after in [true, false] {
            let (y0, gx0, gw0, gb0) = run(Path::Stock, relu_after);
            let (y1, gx1, gw1, gb1) = run(Path::Host, relu_after);
            assert!(max_abs_diff(y0, y1) < 1e-6, "relu {relu_after}: output");
            assert!(max_abs_diff(gx0, gx1) < 1e-6, "relu {relu_after}: input gradient");
            for (name, a, b) in [("weight", gw0, gw1), ("bias", gb0, gb1)] {
                let worst = a.iter().zip(&b).map(|(a, b)| (a - b).abs() / a.abs().max(1.0)).fold(0.0, f32::max);
                assert!(worst < 1e-5, "relu {relu_after}: {name} gradient {worst}");
            }
        }
    }
}
