//! Bicubic resampling as PyTorch's `upsample_bicubic2d` and OpenCV's `INTER_CUBIC` compute it.
//!
//! Both use Keys' cubic convolution with `A = -0.75`, pixel-centre alignment
//! (`src = (dst + 0.5) · ratio - 0.5`, not clamped), and clamp the four taps to the border. They
//! differ only in `ratio`: OpenCV and PyTorch given an output size use `in / out`; PyTorch given a
//! `scale_factor` uses `1 / scale_factor`, which is what DINOv2's position-embedding trick relies
//! on (the `+0.1` makes the output size round down to the patch grid while the ratio stays
//! `sqrt(N) / (grid + 0.1)`). The resize is separable, so it is written as two products with fixed
//! `n_out x n_in` matrices, like [`dgstereo_kernels::resize_bilinear`].

use burn::tensor::{Device, Tensor, TensorData};

/// Keys' cubic-convolution parameter used by PyTorch and OpenCV.
const A: f32 = -0.75;

/// The four tap weights for fractional offset `t` (taps at -1, 0, 1, 2), as PyTorch's
/// `get_cubic_upsample_coefficients`.
fn cubic_coefficients(t: f32) -> [f32; 4] {
    let near = |x: f32| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let far = |x: f32| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    [far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)]
}

/// The `n_out x n_in` row-major matrix of 1-D bicubic interpolation with source ratio `ratio`.
///
/// Output sample `i` reads the input at `(i + 0.5) · ratio - 0.5`; taps outside `0..n_in` are
/// clamped to the border (their weights add onto the edge sample).
pub fn cubic_weights(n_in: usize, n_out: usize, ratio: f32) -> Vec<f32> {
    let mut m = vec![0f32; n_out * n_in];
    for i in 0..n_out {
        let src = ratio * (i as f32 + 0.5) - 0.5;
        let base = src.floor();
        let t = (src - base).clamp(0.0, 1.0);
        let coefficients = cubic_coefficients(t);
        for (k, w) in coefficients.iter().enumerate() {
            let j = (base as i64 + k as i64 - 1).clamp(0, n_in as i64 - 1) as usize;
            m[i * n_in + j] += w;
        }
    }
    m
}

/// Resizes `[N, C, H, W]` to `size` bicubically with explicit source ratios `[ratio_h, ratio_w]`.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, size[0], size[1]]`
pub fn resize_bicubic_with_ratio(x: Tensor<4>, size: [usize; 2], ratio: [f32; 2]) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let device = x.device();
    let a_h = matrix(cubic_weights(h, size[0], ratio[0]), [size[0], h], &device);
    let a_w_t = matrix(cubic_weights(w, size[1], ratio[1]), [size[1], w], &device).transpose();
    let y = a_h.unsqueeze::<4>().expand([n, c, size[0], h]).matmul(x);
    y.matmul(a_w_t.unsqueeze::<4>().expand([n, c, w, size[1]]))
}

/// Resizes `[N, C, H, W]` to `size` as `cv2.resize(..., INTER_CUBIC)` (and PyTorch's bicubic with
/// `align_corners=False` given an output size) do: ratio `in / out` per axis.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, size[0], size[1]]`
pub fn resize_bicubic(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    if [h, w] == size {
        return x;
    }
    let ratio = [h as f32 / size[0] as f32, w as f32 / size[1] as f32];
    resize_bicubic_with_ratio(x, size, ratio)
}

fn matrix(values: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_sum_to_one_and_identity_ratio_is_identity() {
        for (i, o) in [(37, 5), (5, 37), (10, 10), (3, 8)] {
            let m = cubic_weights(i, o, i as f32 / o as f32);
            for r in 0..o {
                let s: f32 = m[r * i..(r + 1) * i].iter().sum();
                assert!((s - 1.0).abs() < 1e-5, "row {r} of {i}->{o} sums to {s}");
            }
        }
        let m = cubic_weights(6, 6, 1.0);
        for r in 0..6 {
            for c in 0..6 {
                let expected = if r == c { 1.0 } else { 0.0 };
                assert!((m[r * 6 + c] - expected).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn taps_are_keys_kernel_with_a_minus_075() {
        // Halfway between samples the kernel with A = -0.75 weighs the taps
        // [-3/32, 19/32, 19/32, -3/32] (A = -0.5 would give [-1/16, 9/16, 9/16, -1/16]).
        let c = cubic_coefficients(0.5);
        for (got, want) in c.iter().zip([-3.0 / 32.0, 19.0 / 32.0, 19.0 / 32.0, -3.0 / 32.0]) {
            assert!((got - want).abs() < 1e-7, "{c:?}");
        }
        assert_eq!(cubic_coefficients(0.0), [0.0, 1.0, 0.0, 0.0]);
        // Upscaling 2x: output 4 reads source 4.5 / 2 - 0.5 = 1.75, taps 0..=3.
        let m = cubic_weights(8, 16, 0.5);
        let c = cubic_coefficients(0.75);
        for k in 0..4 {
            assert!((m[4 * 8 + k] - c[k]).abs() < 1e-7);
        }
        // Output 0 reads -0.25 (not clamped): taps -2..=1, the three below 1 fold onto sample 0.
        assert!((m[0] - (c[0] + c[1] + c[2])).abs() < 1e-7);
        assert!((m[1] - c[3]).abs() < 1e-7);
    }
}
