//! Normalisation of the relative depth prior before it enters a fusion module.
//!
//! Monocular depth networks return relative depth (or disparity) in an arbitrary, per-image
//! scale and offset. The fusion modules see it normalised per image to `[0, 1]` by min-max and
//! then multiplied by 255, so that the depth channel lives in the same range as the RGB channels
//! and one weight initialisation suits both.

use burn::tensor::Tensor;

/// Denominator floor of the min-max normalisation: a constant (or nearly constant) depth map,
/// whose range is below this, normalises to zeros instead of dividing by zero.
pub const DEPTH_RANGE_EPS: f64 = 1e-6;

/// The scale applied after the `[0, 1]` normalisation: the images' range.
pub const IMAGE_RANGE: f64 = 255.0;

/// Normalises a relative depth map per image to `[0, 255]`.
///
/// Each image `b` becomes `255 * (d - min_b) / max(max_b - min_b, DEPTH_RANGE_EPS)`, the minimum
/// and maximum taken over all of that image's channels and pixels. A constant map gives zeros.
/// When `size` differs from the depth's spatial size the normalised map is resized bilinearly
/// (`align_corners = false`) to `size`; min-max happens first, so the result stays in range.
///
/// # Shapes
/// - `depth`: `[N, C, H_d, W_d]` (normally `C = 1`)
/// - output: `[N, C, size[0], size[1]]`
pub fn normalize_depth(depth: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    let [n, c, h, w] = depth.dims();
    let flat = depth.clone().reshape([n, c * h * w]);
    let min = flat.clone().min_dim(1).reshape([n, 1, 1, 1]);
    let max = flat.max_dim(1).reshape([n, 1, 1, 1]);
    let range = (max - min.clone()).clamp_min(DEPTH_RANGE_EPS);
    let unit = (depth - min) / range;
    dgstereo_kernels::resize_bilinear(unit.mul_scalar(IMAGE_RANGE), size, false)
}
