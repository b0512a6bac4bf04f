//! Linear sampling along a row with zero padding, the 1-D `grid_sample` of the reference.

use burn::tensor::{Int, Tensor};

/// The integer taps and weights of sampling at `x + dx` for `dx = -r..=r+1`.
///
/// Linear interpolation at `x + dx` mixes the integer positions `floor(x) + dx` and
/// `floor(x) + dx + 1` with weights `1 - w` and `w`, `w = x - floor(x)`; every tap shares `w`,
/// so `2r + 2` integer positions serve all `2r + 1` samples.
///
/// # Shapes
/// - `x`: `[M, 1]`; returns indices clamped into `0..width` `[M, 2r+2]`, their in-range mask
///   `[M, 2r+2]` (1 or 0) and `w` `[M, 1]`.
pub(crate) fn taps(x: Tensor<2>, radius: usize, width: usize) -> (Tensor<2, Int>, Tensor<2>, Tensor<2>) {
    let [m, _] = x.dims();
    let device = x.device();
    let x0 = x.clone().floor();
    let w = x - x0.clone();
    let n = 2 * radius + 2;
    let offsets = Tensor::<1, Int>::arange(0..n as i64, &device).float().sub_scalar(radius as f64);
    let pos = x0.expand([m, n]) + offsets.unsqueeze::<2>().expand([m, n]);
    let inside =
        pos.clone().greater_equal_elem(0.0).float() * pos.clone().lower_equal_elem((width as f64) - 1.0).float();
    let idx = pos.clamp(0.0, (width as f64) - 1.0).int();
    (idx, inside, w)
}

/// Combines the values at the `2r + 2` integer taps into the `2r + 1` linear samples.
///
/// # Shapes
/// - `values`: `[M, 2r+2]` (already zeroed outside the row), `w`: `[M, 1]`; output `[M, 2r+1]`
pub(crate) fn interpolate_taps(values: Tensor<2>, w: Tensor<2>, radius: usize) -> Tensor<2> {
    let [m, n] = values.dims();
    let k = 2 * radius + 1;
    let lo = values.clone().slice([0..m, 0..n - 1]);
    let hi = values.slice([0..m, 1..n]);
    let w = w.expand([m, k]);
    lo * (w.clone().neg().add_scalar(1.0)) + hi * w
}
