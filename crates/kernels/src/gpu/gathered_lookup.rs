//! The pyramid lookup for GPU inference: every level sampled by two gathers.

use burn::tensor::{Tensor, TensorData};

use crate::taps::tap_offsets;

/// The looked-up levels of a pyramid side by side, and the per-level constants that let one
/// lookup sample all of them with two gathers: the lower and the upper integer tap of every
/// sample. The stock lookup runs a tap computation, a gather and a slice per level (on wgpu the
/// upper taps' slice, one element off the binding alignment, is a copy kernel); this is the same
/// arithmetic in a few fused kernels, for GPU inference.
#[derive(Debug, Clone)]
pub struct GatheredLevels {
    /// `[M, Σ W_i]`: level `i` in the columns `offset_i .. offset_i + W_i`.
    values: Tensor<2>,
    /// `[1, L]`: `1 / 2^i`, the scale of a full-resolution position at level `i`.
    scale: Tensor<2>,
    /// `[1, L, 1]`: `W_i - 1`, the last column of level `i` (-0.5 for an empty level, which
    /// no integer position equals once clamped).
    last: Tensor<3>,
    /// `[1, L, 1]`: `offset_i`, where level `i` starts.
    offset: Tensor<3>,
    /// `[1, 1, 2r+1]`: the tap offsets `-r ..= r`.
    taps: Tensor<3>,
}

impl GatheredLevels {
    /// Lays out `levels` (`[M, W_i]` each) side by side; the constants take the levels' dtype.
    pub fn new(levels: &[Tensor<2>], radius: usize) -> Self {
        let (device, dtype) = (levels[0].device(), levels[0].dtype());
        let widths: Vec<usize> = levels.iter().map(|l| l.dims()[1]).collect();
        let offsets: Vec<f32> =
            widths.iter().scan(0, |start, w| Some(std::mem::replace(start, *start + w) as f32)).collect();
        let l = levels.len();
        let row = |v: Vec<f32>| Tensor::<1>::from_data(TensorData::new(v, [l]), (&device, dtype));
        let k = 2 * radius + 1;
        Self {
            values: Tensor::cat(levels.to_vec(), 1),
            scale: row((0..l).map(|i| 1.0 / (1u64 << i) as f32).collect()).reshape([1, l]),
            last: row(widths.iter().map(|&w| if w == 0 { -0.5 } else { w as f32 - 1.0 }).collect()).reshape([1, l, 1]),
            offset: row(offsets).reshape([1, l, 1]),
            taps: tap_offsets(k, radius, &device, dtype).reshape([1, 1, k]),
        }
    }

    /// Linear samples at `x / 2^i + d`, `d = -r..=r`, of every level `i`, zero outside a level's
    /// row: the stock lookup's values (`ops::lookup::taps`).
    ///
    /// # Shapes
    /// - `x`: `[M, 1]`, in the levels' dtype; output `[M, L·(2r+1)]`, level-major
    pub fn lookup(&self, x: Tensor<2>) -> Tensor<2> {
        let [m, _] = x.dims();
        let [_, l, _] = self.last.dims();
        let k = self.taps.dims()[2];
        if self.values.dims()[1] == 0 {
            return Tensor::zeros([m, l * k], (&x.device(), x.dtype()));
        }
        let xi = x * self.scale.clone(); // [M, L]
        let x0 = xi.clone().floor();
        let w = (xi - x0.clone()).reshape([m, l, 1]);
        let lower = x0.reshape([m, l, 1]) + self.taps.clone(); // [M, L, K]
        let sample = |pos: Tensor<3>| {
            // The position clamped into its level's row; where clamping moved it, the sample lies
            // outside the row and is zero. An empty level's bound, -0.5, moves every position.
            let clamped = pos.clone().clamp_min(0.0).min_pair(self.last.clone().expand([m, l, k]));
            let outside = clamped.clone().not_equal(pos);
            // Truncation takes an empty level's -0.5 to the column before it: a valid index.
            let column = (clamped + self.offset.clone()).int().reshape([m, l * k]);
            self.values.clone().gather(1, column).reshape([m, l, k]).mask_fill(outside, 0.0)
        };
        let upper = sample(lower.clone().add_scalar(1.0));
        let lower = sample(lower);
        (lower * w.clone().neg().add_scalar(1.0) + upper * w).reshape([m, l * k])
    }
}
