//! Pixel masks: which ground-truth pixels are supervised, and EALS's edge mask.

use burn::tensor::{Bool, Tensor};

/// The pixels RAFT-Stereo supervises: `valid >= 0.5` and `|gt| < max_disparity`.
///
/// NaN or infinite ground truth is never supervised (the comparison is false).
///
/// # Shapes
/// - `disparity`, `valid`: `[N, 1, H, W]`
/// - output: `[N, 1, H, W]` boolean
pub fn supervised_mask(disparity: Tensor<4>, valid: Tensor<4>, max_disparity: f64) -> Tensor<4, Bool> {
    valid.greater_equal_elem(0.5).bool_and(disparity.abs().lower_elem(max_disparity))
}

/// EALS's edge mask, `|bilinear - nearest| <= tau`, as 0/1 floats.
///
/// Bilinear and nearest-neighbour resizing of the ground truth agree inside smooth regions and
/// disagree across depth discontinuities, where bilinear interpolation invents disparities that
/// belong to neither surface; those pixels get 0 and are not supervised. With no resize
/// (`bilinear == nearest`) the mask is all ones for any `tau >= 0`. NaN differences give 0.
///
/// # Shapes
/// - `bilinear`, `nearest`: `[N, 1, H, W]`
/// - output: `[N, 1, H, W]`, 1 where kept
pub fn edge_mask(bilinear: Tensor<4>, nearest: Tensor<4>, tau: f64) -> Tensor<4> {
    (bilinear - nearest).abs().lower_equal_elem(tau).float()
}

/// The ground truth with unsupervised pixels set to 0, so that NaN/inf there cannot leak into a
/// loss or its gradient through `0 * inf`.
pub(crate) fn sanitized(disparity: Tensor<4>, supervised: Tensor<4, Bool>) -> Tensor<4> {
    disparity.mask_fill(supervised.bool_not(), 0.0)
}
