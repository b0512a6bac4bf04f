//! Bilinear resizing as products with fixed interpolation matrices.
//!
//! `F.interpolate(x, size, mode="bilinear")` is separable: resizing rows and columns are linear
//! maps, so `y = A_h · x · A_wᵀ` with fixed matrices `A_h` (`H_out x H_in`) and `A_w`. Written this
//! way the resize is two matrix products, whose gradients every burn backend has (the GPU backends
//! lack bilinear-resize backward), and it is exact to PyTorch's formula.

use burn::tensor::{Device, Tensor, TensorData};

/// The `n_out x n_in` matrix of 1-D linear interpolation, row-major.
///
/// With `align_corners` the end samples coincide (`x = i · (n_in-1)/(n_out-1)`), otherwise
/// pixel centres are aligned (`x = (i + 0.5) · n_in/n_out - 0.5`, clamped at 0), as PyTorch and
/// OpenCV's `INTER_LINEAR` do.
pub fn linear_weights(n_in: usize, n_out: usize, align_corners: bool) -> Vec<f32> {
    let mut m = vec![0f32; n_out * n_in];
    for i in 0..n_out {
        let x = if align_corners {
            if n_out > 1 { i as f64 * (n_in as f64 - 1.0) / (n_out as f64 - 1.0) } else { 0.0 }
        } else {
            ((i as f64 + 0.5) * n_in as f64 / n_out as f64 - 0.5).max(0.0)
        };
        let x0 = (x.floor() as usize).min(n_in - 1);
        let x1 = (x0 + 1).min(n_in - 1);
        let w = (x - x0 as f64) as f32;
        m[i * n_in + x0] += 1.0 - w;
        m[i * n_in + x1] += w;
    }
    m
}

/// The interpolation matrix as a `[n_out, n_in]` tensor.
pub fn linear_matrix(n_in: usize, n_out: usize, align_corners: bool, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(linear_weights(n_in, n_out, align_corners), [n_out, n_in]), device)
}

/// Resizes `[N, C, H, W]` to `[N, C, size[0], size[1]]` bilinearly by two matrix products.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, H_out, W_out]`
pub fn resize_bilinear(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    if [h, w] == size {
        return x;
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::module::interpolate;
    use burn::tensor::ops::{InterpolateMode, InterpolateOptions};

    fn stock(x: Tensor<4>, size: [usize; 2], align: bool) -> Tensor<4> {
        let mut o = InterpolateOptions::new(InterpolateMode::Bilinear);
        o.align_corners = align;
        o.output_size = Some(size);
        interpolate(x, o)
    }

    #[test]
    fn matches_stock_bilinear_resize() {
        let device = crate::default_device();
        let x = Tensor::<4>::random([2, 3, 7, 9], burn::tensor::Distribution::Default, &device);
        for size in [[14, 18], [4, 5], [7, 9], [13, 3]] {
            for align in [true, false] {
                let a = resize_bilinear(x.clone(), size, align);
                let b = stock(x.clone(), size, align);
                let diff = crate::tensor::max_abs_diff(a, b);
                assert!(diff < 1e-5, "size {size:?} align {align}: {diff}");
            }
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
}
