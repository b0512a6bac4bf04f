//! Convex upsampling of the disparity field.
//!
//! Design decision: burn's operations are the reference and run everywhere (training, the GPU);
//! CPU inference (the dispatch's host path) takes a host pass instead, one parallel sweep that
//! computes each coarse pixel's softmax weights once and writes its `factor x factor` block of
//! every channel. The stock composition (softmax over a reshaped mask, `unfold`, a broadcast
//! product, a sum and a permute) ran mostly on one core: 35-90 ms of a 384x448 pass on the
//! Xeon, as much as one update iteration.

use burn::tensor::activation::softmax;
use burn::tensor::module::unfold4d;
use burn::tensor::ops::UnfoldOptions;
use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::{host_values, zeros_parallel};
use dgstereo_kernels::{Op, Path, path};
use rayon::prelude::*;

/// Upsamples `[N, D, H, W]` by `factor` as a convex combination of each coarse pixel's 3x3
/// neighbourhood, with weights from `mask` (softmax over the 9); values are scaled by `factor`.
///
/// This is RAFT's `upsample_flow`: zero padding at the border, as `F.unfold(padding=1)`.
///
/// # Shapes
/// - `flow`: `[N, D, H, W]`, `mask`: `[N, 9·factor², H, W]`; output `[N, D, factor·H, factor·W]`
pub fn convex_upsample(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    if path(&flow.device(), Op::Upsample) == Path::Host && path(&mask.device(), Op::Upsample) == Path::Host {
        return convex_upsample_host(flow, mask, factor);
    }
    convex_upsample_stock(flow, mask, factor)
}

/// [`convex_upsample`] in burn's operations: the reference, and the path wherever the host
/// kernels do not apply.
fn convex_upsample_stock(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let [n, d, h, w] = flow.dims();
    let ff = factor * factor;
    let mask = softmax(mask.reshape([n, 1, 9, ff, h * w]), 2);
    let patches = unfold4d(flow.mul_scalar(factor as f64), [3, 3], UnfoldOptions::new([1, 1], [1, 1], [1, 1]));
    let patches = patches.reshape([n, d, 9, 1, h * w]);
    let up = (mask * patches).sum_dim(2); // [n, d, 1, ff, hw]
    up.reshape([n, d, factor, factor, h, w]).permute([0, 1, 4, 2, 5, 3]).reshape([n, d, factor * h, factor * w])
}

/// [`convex_upsample`] on the host: per image and coarse row, the softmax weights of the row's
/// pixels (`[W][factor²][9]`), then the `factor` output rows of every channel.
///
/// # Panics
/// When `mask` does not have `9·factor²` channels of `flow`'s batch and size.
fn convex_upsample_host(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let (device, [n, d, h, w]) = (flow.device(), flow.dims());
    let ff = factor * factor;
    assert_eq!(mask.dims(), [n, 9 * ff, h, w], "convex_upsample: the mask is not [{n}, {}, {h}, {w}]", 9 * ff);
    let (flow, mask) = (host_values(flow), host_values(mask));
    let (plane, wide) = (h * w, factor * w);
    let mut out = zeros_parallel(n * d * plane * ff);
    // One job per (image, coarse row): its `factor` output rows in each of the `d` channels.
    let mut jobs: Vec<Vec<&mut [f32]>> = (0..n * h).map(|_| Vec::with_capacity(d)).collect();
    for (i, rows) in out.chunks_mut(factor * wide).enumerate() {
        let (b, y) = (i / (d * h), i % h);
        jobs[b * h + y].push(rows);
    }
    jobs.into_par_iter().enumerate().for_each_init(Vec::new, |weights, (job, mut rows)| {
        let (b, y) = (job / h, job % h);
        // weights[(x·ff + s)·9 + k]: the softmax over the 9 taps of subpixel `s` of pixel x.
        weights.resize(w * ff * 9, 0.0);
        let mask = &mask[b * 9 * ff * plane..][..9 * ff * plane];
        for x in 0..w {
            for s in 0..ff {
                let at = |k: usize| mask[(k * ff + s) * plane + y * w + x];
                let top = (0..9).map(at).fold(f32::NEG_INFINITY, f32::max);
                let dst = &mut weights[(x * ff + s) * 9..][..9];
                let mut sum = 0.0;
                for (k, e) in dst.iter_mut().enumerate() {
                    *e = (at(k) - top).exp();
                    sum += *e;
                }
                dst.iter_mut().for_each(|e| *e /= sum);
            }
        }
        for (c, rows) in rows.iter_mut().enumerate() {
            let flow = &flow[(b * d + c) * plane..][..plane];
            // The 3x3 neighbourhood of (y, x), zero outside, times `factor`.
            let value = |yy: usize, xx: usize| {
                let inside = (1..=h).contains(&yy) && (1..=w).contains(&xx);
                if inside { flow[(yy - 1) * w + xx - 1] * factor as f32 } else { 0.0 }
            };
            for x in 0..w {
                let taps: [f32; 9] = std::array::from_fn(|k| value(y + k / 3, x + k % 3));
                for s in 0..ff {
                    let weight = &weights[(x * ff + s) * 9..][..9];
                    let v = weight.iter().zip(&taps).map(|(a, t)| a * t).sum::<f32>();
                    rows[(s / factor) * wide + x * factor + s % factor] = v;
                }
            }
        }
    });
    Tensor::from_data(TensorData::new(out, [n, d, factor * h, factor * w]), &device)
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::{max_abs_diff, to_vec};

    use super::*;

    /// The host pass against burn's composition, two images, two channels, a mask with large
    /// logits, factors 2 and 4, grids down to one pixel (every tap of the border padding).
    #[test]
    fn the_host_pass_equals_the_stock_composition() {
        let device = Device::flex();
        for (factor, [h, w]) in [(4, [5, 7]), (2, [3, 1]), (4, [1, 1])] {
            let flow = Tensor::<4>::random([2, 2, h, w], Distribution::Normal(0.0, 10.0), &device);
            let mask = Tensor::<4>::random([2, 9 * factor * factor, h, w], Distribution::Normal(0.0, 8.0), &device);
            let host = convex_upsample_host(flow.clone(), mask.clone(), factor);
            let stock = convex_upsample_stock(flow, mask, factor);
            assert_eq!(host.dims(), stock.dims());
            let scale = to_vec(stock.clone()).iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let diff = max_abs_diff(host.clone(), stock);
            assert!(diff <= 1e-5 * scale.max(1.0), "factor {factor}, {h}x{w}: {diff} (scale {scale})");
        }
    }
}
