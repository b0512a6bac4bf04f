//! Convex upsampling of the disparity field.
//!
//! Design decision: burn's operations are the reference and run wherever the host kernels do not
//! (the GPU, `stock` settings); the CPU (the dispatch's host path) takes a host pass instead
//! (`crate::host::upsample`; in training with its own backward, `crate::autodiff::upsample`),
//! one parallel sweep that computes each coarse pixel's softmax weights once and writes its
//! `factor x factor` block of every channel. The stock composition (softmax over a reshaped
//! mask, `unfold`, a broadcast product, a sum and a permute) is several passes that burn's CPU
//! backend runs mostly on one core.

use burn::tensor::Tensor;
use burn::tensor::activation::softmax;
use burn::tensor::module::unfold4d;
use burn::tensor::ops::UnfoldOptions;

use crate::dispatch::{Op, PlainCall, Plan, plan};
use crate::host::upsample::convex_upsample_host;

/// Upsamples `[N, D, H, W]` by `factor` as a convex combination of each coarse pixel's 3x3
/// neighbourhood, with weights from `mask` (softmax over the 9); values are scaled by `factor`.
///
/// This is RAFT's `upsample_flow`: zero padding at the border, as `F.unfold(padding=1)`.
///
/// # Shapes
/// - `flow`: `[N, D, H, W]`, `mask`: `[N, 9·factor², H, W]`; output `[N, D, factor·H, factor·W]`
pub fn convex_upsample(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::convex_upsample_macs(flow.dims(), factor));
    let call = PlainCall(Op::Upsample);
    match (plan(&flow.device(), &call), plan(&mask.device(), &call)) {
        (Plan::HostTraining(()), Plan::HostTraining(())) => {
            crate::autodiff::upsample::convex_upsample(flow, mask, factor)
        }
        (Plan::HostInference(()), Plan::HostInference(())) => convex_upsample_host(flow, mask, factor),
        _ => convex_upsample_stock(flow, mask, factor),
    }
}

/// [`convex_upsample`] in burn's operations: the reference, and the path wherever the host
/// kernels do not apply.
fn convex_upsample_stock(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let [n, d, h, w] = flow.dims();
    let ff = factor * factor;
    let mask = softmax(mask.reshape([n, 1, 9, ff, h * w]), 2);
    let patches = unfold4d(flow.mul_scalar(factor as f64), [3, 3], UnfoldOptions::new([1, 1], [1, 1], [1, 1]));
    let patches = patches.reshape([n, d, 9, 1, h * w]);
    let up = (mask * patches).sum_dim(2); // [n, d, 1, ff, hw]
    up.reshape([n, d, factor, factor, h, w]).permute([0, 1, 4, 2, 5, 3]).reshape([n, d, factor * h, factor * w])
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::{max_abs_diff, to_vec};

    use super::*;
    use crate::dispatch::{Path, with_path};

    /// The host pass against burn's composition, two images, two channels, a mask with large
    /// logits, factors 2 and 4, grids down to one pixel (every tap of the border padding).
    #[test]
    fn the_host_pass_equals_the_stock_composition() {
        let device = Device::flex();
        for (factor, [h, w]) in [(4, [5, 7]), (2, [3, 1]), (4, [1, 1])] {
            let flow = Tensor::<4>::random([2, 2, h, w], Distribution::Normal(0.0, 10.0), &device);
            let mask = Tensor::<4>::random([2, 9 * factor * factor, h, w], Distribution::Normal(0.0, 8.0), &device);
            let host = convex_upsample_host(flow.clone(), mask.clone(), factor);
            let stock = convex_upsample_stock(flow, mask, factor);
            assert_eq!(host.dims(), stock.dims());
            let scale = to_vec(stock.clone()).iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let diff = max_abs_diff(host.clone(), stock);
            assert!(diff <= 1e-5 * scale.max(1.0), "factor {factor}, {h}x{w}: {diff} (scale {scale})");
        }
    }

    /// The training node's (`crate::autodiff::upsample`) flow and mask gradients against burn's
    /// autodiff of the stock composition
    /// (the loss `Σ up·r` with a random `r`): one and two channels, two images, factors 2 and 4,
    /// grids down to one pixel (every tap in the border padding), a mask with large logits.
    #[test]
    fn the_training_gradients_agree_with_burns_autodiff() {
        let ad = Device::flex().autodiff();
        for (n, d, factor, [h, w]) in [(2, 1, 4, [5, 7]), (1, 2, 2, [3, 1]), (2, 2, 4, [1, 1]), (1, 1, 4, [6, 6])] {
            let flow = Tensor::<4>::random([n, d, h, w], Distribution::Normal(0.0, 5.0), &ad);
            let mask = Tensor::<4>::random([n, 9 * factor * factor, h, w], Distribution::Normal(0.0, 4.0), &ad);
            let r = Tensor::<4>::random([n, d, factor * h, factor * w], Distribution::Normal(0.0, 1.0), &ad);
            let run = |pinned: Path| {
                let (flow, mask) = (flow.clone().detach().require_grad(), mask.clone().detach().require_grad());
                let up =
                    with_path(pinned, || crate::ops::upsample::convex_upsample(flow.clone(), mask.clone(), factor));
                let grads = (up.clone() * r.clone()).sum().backward();
                let grad = |t: &Tensor<4>| to_vec(t.grad(&grads).expect("a gradient"));
                (to_vec(up.detach()), grad(&flow), grad(&mask))
            };
            let (ours, stock) = (run(Path::Host), run(Path::Stock));
            let case = format!("n {n} d {d} factor {factor} {h}x{w}");
            for (what, got, want) in
                [("output", &ours.0, &stock.0), ("flow", &ours.1, &stock.1), ("mask", &ours.2, &stock.2)]
            {
                let scale = want.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
                let worst = got.iter().zip(want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale;
                assert!(worst < 1e-5, "{case}: {what} gradient differs by {worst:e} of its largest value");
            }
        }
    }

    crate::test_paths!(
        /// Every path upsamples as burn's composition does.
        fn every_path_upsamples_as_the_reference(pinned) {
            let device = Device::flex();
            let flow = Tensor::<4>::random([2, 2, 5, 7], Distribution::Normal(0.0, 3.0), &device);
            let mask = Tensor::<4>::random([2, 9 * 16, 5, 7], Distribution::Normal(0.0, 1.0), &device);
            let want = convex_upsample_stock(flow.clone(), mask.clone(), 4);
            let diff = max_abs_diff(want, convex_upsample(flow, mask, 4));
            assert!(diff < 1e-5, "{pinned:?}: {diff}");
        }
    );
}
