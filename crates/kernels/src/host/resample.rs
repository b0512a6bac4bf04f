//! The resampling host passes for CPU inference: bilinear resize with the two taps of each
//! output row and column, and the GRUs' 2x average pooling, each in parallel over channel planes.
//!
//! Design decision: the stock resize is two products with interpolation matrices, which spend
//! most of their work on the matrices' zeros, and burn Flex's pooling runs on one thread; here
//! each output reads only the inputs it weighs.

use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::{host_values, zeros_parallel};
use rayon::prelude::*;

/// The two taps of each output sample of 1-D linear interpolation: `(x0, x1, w)`, the output
/// being `(1 - w)·in[x0] + w·in[x1]` (`x1 == x0` at the last sample).
///
/// With `align_corners` the end samples coincide (`x = i · (n_in-1)/(n_out-1)`), otherwise
/// pixel centres are aligned (`x = (i + 0.5) · n_in/n_out - 0.5`, clamped at 0), as PyTorch and
/// OpenCV's `INTER_LINEAR` do.
pub(crate) fn linear_taps(n_in: usize, n_out: usize, align_corners: bool) -> Vec<(usize, usize, f32)> {
    (0..n_out)
        .map(|i| {
            let x = if align_corners {
                if n_out > 1 { i as f64 * (n_in as f64 - 1.0) / (n_out as f64 - 1.0) } else { 0.0 }
            } else {
                ((i as f64 + 0.5) * n_in as f64 / n_out as f64 - 0.5).max(0.0)
            };
            let x0 = (x.floor() as usize).min(n_in - 1);
            let x1 = (x0 + 1).min(n_in - 1);
            (x0, x1, (x - x0 as f64) as f32)
        })
        .collect()
}

/// `crate::resize_bilinear` on the host: rows, then columns, two taps each, per channel plane.
pub(crate) fn resize_bilinear_host(x: Tensor<4>, [ho, wo]: [usize; 2], align_corners: bool) -> Tensor<4> {
    let (device, [n, c, h, w]) = (x.device(), x.dims());
    let (rows, columns) = (linear_taps(h, ho, align_corners), linear_taps(w, wo, align_corners));
    let values = host_values(x);
    let mut out = zeros_parallel(n * c * ho * wo);
    if !out.is_empty() && h * w > 0 {
        // A row step blends two whole rows (vector operations); a column step gathers two taps
        // per output value. Upsampling rows, the columns go first, on the `h` input rows rather
        // than the `ho` output rows: half the gathers at the GRUs' 2x upsampling. Either order is
        // the same interpolation up to rounding.
        let columns_first = ho > h;
        out.par_chunks_mut(ho * wo).zip(values.par_chunks(h * w)).for_each_init(Vec::new, |tmp, (dst, src)| {
            let blend_rows = |dst: &mut [f32], src: &[f32], width: usize| {
                for (line, &(y0, y1, t)) in dst.chunks_exact_mut(width).zip(&rows) {
                    let (a, b) = (&src[y0 * width..][..width], &src[y1 * width..][..width]);
                    for ((d, a), b) in line.iter_mut().zip(a).zip(b) {
                        *d = (1.0 - t) * a + t * b;
                    }
                }
            };
            let blend_columns = |dst: &mut [f32], src: &[f32]| {
                for (line, src) in dst.chunks_exact_mut(wo).zip(src.chunks_exact(w)) {
                    for (d, &(x0, x1, t)) in line.iter_mut().zip(&columns) {
                        *d = (1.0 - t) * src[x0] + t * src[x1];
                    }
                }
            };
            if columns_first {
                tmp.resize(h * wo, 0.0);
                blend_columns(tmp, src);
                blend_rows(dst, tmp, wo);
            } else {
                tmp.resize(ho * w, 0.0);
                blend_rows(tmp, src, w);
                blend_columns(dst, tmp);
            }
        });
    }
    Tensor::from_data(TensorData::new(out, [n, c, ho, wo]), &device)
}

/// `crate::average_pool_half` on the host: per channel plane, the three rows of each window
/// summed, then the three columns.
pub(crate) fn average_pool_half_host(x: Tensor<4>) -> Tensor<4> {
    let (device, [n, c, h, w]) = (x.device(), x.dims());
    let (ho, wo) = ((h.max(1) - 1) / 2 + 1, (w.max(1) - 1) / 2 + 1);
    let values = host_values(x);
    let mut out = zeros_parallel(n * c * ho * wo);
    if h * w > 0 {
        out.par_chunks_mut(ho * wo).zip(values.par_chunks(h * w)).for_each_init(Vec::new, |sums, (dst, src)| {
            // One row of vertical window sums, with a zero column on each side (the padding).
            sums.resize(w + 2, 0.0);
            for (oy, line) in dst.chunks_exact_mut(wo).enumerate() {
                let row = |y: usize| &src[y * w..][..w];
                let (centre, below) = (row(2 * oy), (2 * oy + 1 < h).then(|| row(2 * oy + 1)));
                let above = oy.checked_sub(1).map(|_| row(2 * oy - 1));
                let inner = &mut sums[1..=w];
                inner.copy_from_slice(centre);
                for r in [above, below].into_iter().flatten() {
                    inner.iter_mut().zip(r).for_each(|(s, v)| *s += v);
                }
                // Output column ox covers padded columns 2·ox .. 2·ox + 2.
                for (ox, d) in line.iter_mut().enumerate() {
                    *d = (sums[2 * ox] + sums[2 * ox + 1] + sums[2 * ox + 2]) / 9.0;
                }
            }
        });
    }
    Tensor::from_data(TensorData::new(out, [n, c, ho, wo]), &device)
}
