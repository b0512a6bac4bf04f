//! Bilinear resizing as products with fixed interpolation matrices, and the GRUs' 2x average
//! pooling.
//!
//! `F.interpolate(x, size, mode="bilinear")` is separable: resizing rows and columns are linear
//! maps, so `y = A_h · x · A_wᵀ` with fixed matrices `A_h` (`H_out x H_in`) and `A_w`. Written this
//! way the resize is two matrix products, whose gradients every burn backend has (the GPU backends
//! lack bilinear-resize backward), and it is exact to PyTorch's formula. For CPU inference
//! (the dispatch's host path) the same interpolation runs as a host pass with the two taps of each
//! output row and column, in parallel over channel planes (`crate::host::resample`): the products
//! spend most of their work on the matrices' zeros. GPU
//! inference (route `resize`) takes burn's `interpolate`, one kernel where the products
//! take two and upload their matrices on every call; training keeps the products everywhere.

use burn::tensor::module::{avg_pool2d, interpolate};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};

use crate::dispatch::{Op, PlainCall, Plan, plan};
use crate::host::resample::{average_pool_half_host, linear_taps, resize_bilinear_host};

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
    match plan(&x.device(), &PlainCall(Op::Resize)) {
        Plan::HostInference(()) => resize_bilinear_host(x, size, align_corners),
        Plan::Gpu(()) => resize_bilinear_by_interpolate(x, size, align_corners),
        Plan::HostTraining(()) | Plan::Stock => resize_bilinear_by_matrices(x, size, align_corners),
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

/// `F.avg_pool2d(x, 3, stride=2, padding=1)`: the mean of each 3x3 window at stride 2, the zero
/// padding counted in the mean (PyTorch's default `count_include_pad`), so every output is its
/// window's sum over 9. For CPU inference (the dispatch's host path) a host pass per channel
/// plane (`crate::host::resample`); elsewhere burn's `avg_pool2d`.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, C, (H - 1) / 2 + 1, (W - 1) / 2 + 1]`
pub fn average_pool_half(x: Tensor<4>) -> Tensor<4> {
    match plan(&x.device(), &PlainCall(Op::Pool)) {
        Plan::HostInference(()) => average_pool_half_host(x),
        Plan::HostTraining(()) | Plan::Gpu(()) | Plan::Stock => {
            let options = AvgPoolOptions::new([3, 3]).with_stride([2, 2]).with_padding([1, 1]);
            avg_pool2d(x, options)
        }
    }
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
