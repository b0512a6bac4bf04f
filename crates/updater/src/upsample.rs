//! Convex upsampling of the disparity field.

use burn::tensor::Tensor;
use burn::tensor::activation::softmax;
use burn::tensor::module::unfold4d;
use burn::tensor::ops::UnfoldOptions;

/// Upsamples `[N, D, H, W]` by `factor` as a convex combination of each coarse pixel's 3x3
/// neighbourhood, with weights from `mask` (softmax over the 9); values are scaled by `factor`.
///
/// This is RAFT's `upsample_flow`: zero padding at the border, as `F.unfold(padding=1)`.
///
/// # Shapes
/// - `flow`: `[N, D, H, W]`, `mask`: `[N, 9·factor², H, W]`; output `[N, D, factor·H, factor·W]`
pub fn convex_upsample(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let [n, d, h, w] = flow.dims();
    let ff = factor * factor;
    let mask = softmax(mask.reshape([n, 1, 9, ff, h * w]), 2);
    let patches = unfold4d(flow.mul_scalar(factor as f64), [3, 3], UnfoldOptions::new([1, 1], [1, 1], [1, 1]));
    let patches = patches.reshape([n, d, 9, 1, h * w]);
    let up = (mask * patches).sum_dim(2); // [n, d, 1, ff, hw]
    up.reshape([n, d, factor, factor, h, w]).permute([0, 1, 4, 2, 5, 3]).reshape([n, d, factor * h, factor * w])
}
