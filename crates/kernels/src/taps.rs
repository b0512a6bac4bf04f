//! Linear sampling along a row with zero padding, the 1-D `grid_sample` of the reference: the
//! taps the stock lookups and the GPU's gathered lookup share.

use burn::tensor::{DType, Device, FloatDType, Int, Tensor, TensorData};
use dgstereo_core::tensor::cast_float;

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
    // Everything in the positions' dtype (f32 in half precision too, see the model's forward).
    let (device, dtype) = (x.device(), x.dtype());
    let x0 = x.clone().floor();
    let w = x - x0.clone();
    let n = 2 * radius + 2;
    let offsets = tap_offsets(n, radius, &device, dtype);
    let pos = x0.expand([m, n]) + offsets.unsqueeze::<2>().expand([m, n]);
    let inside = cast_float(
        pos.clone().greater_equal_elem(0.0).float() * pos.clone().lower_equal_elem((width as f64) - 1.0).float(),
        FloatDType::from(dtype),
    );
    let idx = pos.clamp(0.0, (width as f64) - 1.0).int();
    (idx, inside, w)
}

/// The tap offsets `-r, -r + 1, …` (`count` of them) as a tensor of `dtype` on `device`.
pub(crate) fn tap_offsets(count: usize, radius: usize, device: &Device, dtype: DType) -> Tensor<1> {
    let offsets: Vec<f32> = (0..count).map(|j| j as f32 - radius as f32).collect();
    Tensor::from_data(TensorData::new(offsets, [count]), (device, dtype))
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
