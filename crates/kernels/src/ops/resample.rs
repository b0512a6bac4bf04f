//! Bilinear resizing as products with fixed interpolation matrices, and the GRUs' 2x average
//! pooling.
//!
//! `F.interpolate(x, size, mode="bilinear")` is separable: resizing rows and columns are linear
//! maps, so `y = A_h · x · A_wᵀ` with fixed matrices `A_h` (`H_out x H_in`) and `A_w`. Written this
//! way the resize is two matrix products, whose gradients every burn backend has (the GPU backends
//! lack bilinear-resize backward), and it is exact to PyTorch's formula. For CPU inference
//! (the dispatch's host path) the same interpolation runs as a host pass with the two taps of each
//! output row and column, in parallel over channel planes: the products spend most of their work
//! on the matrices' zeros (the GRUs' resizes between levels were 4 % of a CPU forward pass). GPU
//! inference (route `resize`) takes burn's `interpolate`, one kernel where the products
//! take two and upload their matrices on every call; training keeps the products everywhere.

use burn::tensor::module::{avg_pool2d, interpolate};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;

use dgstereo_core::tensor::{host_values, zeros_parallel};

use crate::dispatch::{Op, Path, path};

/// The two taps of each output sample of 1-D linear interpolation: `(x0, x1, w)`, the output
/// being `(1 - w)·in[x0] + w·in[x1]` (`x1 == x0` at the last sample).
///
/// With `align_corners` the end samples coincide (`x = i · (n_in-1)/(n_out-1)`), otherwise
/// pixel centres are aligned (`x = (i + 0.5) · n_in/n_out - 0.5`, clamped at 0), as PyTorch and
/// OpenCV's `INTER_LINEAR` do.
fn linear_taps(n_in: usize, n_out: usize, align_corners: bool) -> Vec<(usize, usize, f32)> {
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

/// The `n_out x n_in` matrix of 1-D linear interpolation, row-major (the taps of
/// `linear_taps`).
pub fn linear_weights(n_in: usize, n_out: usize, align_corners: bool) -> Vec<f32> {
    let mut m = vec![0f32; n_out * n_in];
    for (i, (x0, x1, w)) in linear_taps(n_in, n_out, align_corners).into_iter().enumerate() {
        m[i * n_in + x0] += 1.0 - w;
        m[i * n_in + x1] += w;
    }
    m
}

/// The interpolation matrix as a `[n_out, n_in]` tensor.
pub fn linear_matrix(n_in: usize, n_out: usize, align_corners: bool, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(linear_weights(n_in, n_out, align_corners), [n_out, n_in]), device)
}

/// Resizes `[N, C, H, W]` to `[N, C, size[0], size[1]]` bilinearly: by two matrix products, or
/// by the host pass for CPU inference.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, H_out, W_out]`
pub fn resize_bilinear(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    if [h, w] == size {
        return x;
    }
    match path(&x.device(), Op::Resize) {
        Path::Host => resize_bilinear_host(x, size, align_corners),
        Path::Gpu => resize_bilinear_by_interpolate(x, size, align_corners),
        Path::Stock => resize_bilinear_by_matrices(x, size, align_corners),
    }
}

/// [`resize_bilinear`] by burn's `interpolate` (forward only on the GPU backends).
fn resize_bilinear_by_interpolate(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    let mut options = InterpolateOptions::new(InterpolateMode::Bilinear);
    options.align_corners = align_corners;
    options.output_size = Some(size);
    interpolate(x, options)
}

/// [`resize_bilinear`] by the two matrix products (the reference; every backend, with gradients).
fn resize_bilinear_by_matrices(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let device = x.device();
    let mut y = x;
    if h != size[0] {
        let a_h = linear_matrix(h, size[0], align_corners, &device);
        y = a_h.unsqueeze::<4>().expand([n, c, size[0], h]).matmul(y);
    }
    if w != size[1] {
        let a_w_t = linear_matrix(w, size[1], align_corners, &device).transpose();
        y = y.matmul(a_w_t.unsqueeze::<4>().expand([n, c, w, size[1]]));
    }
    y
}

/// [`resize_bilinear`] on the host: rows, then columns, two taps each, per channel plane.
fn resize_bilinear_host(x: Tensor<4>, [ho, wo]: [usize; 2], align_corners: bool) -> Tensor<4> {
    let (device, [n, c, h, w]) = (x.device(), x.dims());
    let (rows, columns) = (linear_taps(h, ho, align_corners), linear_taps(w, wo, align_corners));
    let values = host_values(x);
    let mut out = zeros_parallel(n * c * ho * wo);
    if !out.is_empty() && h * w > 0 {
        // A row step blends two whole rows (vector operations); a column step gathers two taps
        // per output value. Upsampling rows, the columns go first, on the `h` input rows rather
        // than the `ho` output rows: half the gathers at the GRUs' 2x upsampling (the 1/8 state to
        // 1/4 of 384x448, one process alternating both orders, median of 57: 2.49 -> 1.97 ms; 1/16
        // to 1/8 0.61 -> 0.45 ms). Either order is the same interpolation up to rounding.
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

/// `F.avg_pool2d(x, 3, stride=2, padding=1)`: the mean of each 3x3 window at stride 2, the zero
/// padding counted in the mean (PyTorch's default `count_include_pad`), so every output is its
/// window's sum over 9. For CPU inference (the dispatch's host path) a host pass per channel plane
/// (the three rows summed, then the three columns); elsewhere burn's `avg_pool2d`. burn Flex's
/// pooling took 9.2 ms for the GRUs' 1/4 state at 384x448 (128 x 96 x 112), ~4 % of an update
/// iteration on the Xeon; the host pass 1.2 ms.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, C, (H - 1) / 2 + 1, (W - 1) / 2 + 1]`
pub fn average_pool_half(x: Tensor<4>) -> Tensor<4> {
    if path(&x.device(), Op::Pool) != Path::Host {
        let options = AvgPoolOptions::new([3, 3]).with_stride([2, 2]).with_padding([1, 1]);
        return avg_pool2d(x, options);
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// burn's resize: the reference.
    fn stock(x: Tensor<4>, size: [usize; 2], align: bool) -> Tensor<4> {
        resize_bilinear_by_interpolate(x, size, align)
    }

    #[test]
    fn matches_stock_bilinear_resize() {
        let device = Device::flex();
        let x = Tensor::<4>::random([2, 3, 7, 9], burn::tensor::Distribution::Default, &device);
        for size in [[14, 18], [4, 5], [7, 9], [13, 3]] {
            for align in [true, false] {
                let b = stock(x.clone(), size, align);
                for (path, a) in [
                    ("entry", resize_bilinear(x.clone(), size, align)),
                    ("matrices", resize_bilinear_by_matrices(x.clone(), size, align)),
                ] {
                    let diff = dgstereo_core::tensor::max_abs_diff(a, b.clone());
                    assert!(diff < 1e-5, "{path}, size {size:?} align {align}: {diff}");
                }
            }
        }
    }

    /// The host pass against the matrix products (the reference), upsampling, downsampling and
    /// one axis only, with and without aligned corners.
    #[test]
    fn host_resize_matches_the_matrix_products() {
        let device = Device::flex();
        let x = Tensor::<4>::random([2, 3, 6, 7], burn::tensor::Distribution::Default, &device);
        for size in [[11, 13], [3, 4], [6, 14], [12, 7], [1, 1]] {
            for align in [true, false] {
                let host = resize_bilinear_host(x.clone(), size, align);
                let reference = resize_bilinear_by_matrices(x.clone(), size, align);
                assert_eq!(host.dims(), reference.dims());
                let diff = dgstereo_core::tensor::max_abs_diff(host, reference);
                assert!(diff < 1e-6, "size {size:?} align {align}: {diff}");
            }
        }
        // The public entry takes the host pass on the plain CPU device.
        let via_entry = resize_bilinear(x.clone(), [11, 13], true);
        let host = resize_bilinear_host(x, [11, 13], true);
        assert_eq!(dgstereo_core::tensor::max_abs_diff(via_entry, host), 0.0);
    }

    /// The host pooling against burn's `avg_pool2d` (the reference) on even and odd sizes, one row
    /// or column, and a single pixel.
    #[test]
    fn host_average_pool_matches_burn() {
        let device = Device::flex();
        let options = AvgPoolOptions::new([3, 3]).with_stride([2, 2]).with_padding([1, 1]);
        for [h, w] in [[8, 10], [7, 9], [1, 6], [5, 1], [1, 1], [2, 3]] {
            let x = Tensor::<4>::random([2, 3, h, w], burn::tensor::Distribution::Default, &device);
            let reference = avg_pool2d(x.clone(), options.clone());
            let host = average_pool_half(x);
            assert_eq!(host.dims(), reference.dims(), "{h}x{w}");
            let diff = dgstereo_core::tensor::max_abs_diff(host, reference);
            assert!(diff < 1e-6, "{h}x{w}: {diff}");
        }
    }

    #[test]
    fn rows_sum_to_one() {
        for (i, o) in [(5, 9), (9, 5), (1, 4), (4, 1)] {
            for align in [true, false] {
                let m = linear_weights(i, o, align);
                for r in 0..o {
                    let s: f32 = m[r * i..(r + 1) * i].iter().sum();
                    assert!((s - 1.0).abs() < 1e-6);
                }
            }
        }
    }

    crate::test_paths!(
        /// Every path resizes as the interpolation matrices do (up, down, both corner rules) and
        /// pools as burn's `avg_pool2d`.
        fn every_path_resamples_as_the_reference(pinned) {
            let device = Device::flex();
            let x = Tensor::<4>::random([2, 3, 9, 13], burn::tensor::Distribution::Normal(0.0, 1.0), &device);
            for size in [[5, 7], [18, 26], [9, 20]] {
                for align_corners in [false, true] {
                    let want = resize_bilinear_by_matrices(x.clone(), size, align_corners);
                    let diff = dgstereo_core::tensor::max_abs_diff(want, resize_bilinear(x.clone(), size, align_corners));
                    assert!(diff < 1e-5, "{pinned:?} {size:?} align {align_corners}: {diff}");
                }
            }
            let options = AvgPoolOptions::new([3, 3]).with_stride([2, 2]).with_padding([1, 1]);
            let want = avg_pool2d(x.clone(), options);
            let diff = dgstereo_core::tensor::max_abs_diff(want, average_pool_half(x));
            assert!(diff < 1e-6, "{pinned:?} pooling: {diff}");
        }
    );
}
