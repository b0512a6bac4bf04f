//! Convex upsampling on the host: one parallel sweep that computes each coarse pixel's softmax
//! weights once and writes its `factor x factor` block of every channel.

use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::{host_values, zeros_parallel};
use rayon::prelude::*;

use crate::geometry::band_jobs;

/// Convex upsampling (`crate::ops::upsample::convex_upsample`) on the host: per image and
/// coarse row, the softmax weights of the row's pixels (`[W][factor²][9]`), then the `factor`
/// output rows of every channel.
///
/// # Panics
/// When `mask` does not have `9·factor²` channels of `flow`'s batch and size.
pub fn convex_upsample_host(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let (device, dims) = (flow.device(), flow.dims());
    let [n, d, h, w] = dims;
    let out = convex_upsample_values(&host_values(flow), &host_values(mask), dims, factor);
    Tensor::from_data(TensorData::new(out, [n, d, factor * h, factor * w]), &device)
}

/// [`convex_upsample_host`] on host buffers: `flow` `[N, D, H, W]`, `mask` `[N, 9·factor², H, W]`;
/// returns `[N, D, factor·H, factor·W]`.
///
/// # Panics
/// When `mask` does not have `9·factor²` channels of `flow`'s batch and size.
pub fn convex_upsample_values(flow: &[f32], mask: &[f32], [n, d, h, w]: [usize; 4], factor: usize) -> Vec<f32> {
    let ff = factor * factor;
    let plane = h * w;
    assert_eq!(flow.len(), n * d * plane, "convex_upsample: the flow is not [{n}, {d}, {h}, {w}]");
    assert_eq!(mask.len(), n * 9 * ff * plane, "convex_upsample: the mask is not [{n}, {}, {h}, {w}]", 9 * ff);
    let wide = factor * w;
    let mut out = zeros_parallel(n * d * plane * ff);
    // One job per (image, coarse row): its `factor` output rows in each of the `d` channels.
    let jobs = band_jobs(&mut out, d, plane * ff, (factor * wide).max(1));
    jobs.into_par_iter().enumerate().for_each_init(Vec::new, |weights, (job, mut rows)| {
        let (b, y) = (job / h, job % h);
        softmax_weights(weights, &mask[b * 9 * ff * plane..][..9 * ff * plane], [h, w], y, ff);
        for (c, rows) in rows.iter_mut().enumerate() {
            let flow = &flow[(b * d + c) * plane..][..plane];
            for x in 0..w {
                let taps = neighbourhood(flow, [h, w], y, x, factor);
                for s in 0..ff {
                    let weight = &weights[(x * ff + s) * 9..][..9];
                    let v = weight.iter().zip(&taps).map(|(a, t)| a * t).sum::<f32>();
                    rows[(s / factor) * wide + x * factor + s % factor] = v;
                }
            }
        }
    });
    out
}

/// Fills `weights[(x·ff + s)·9 + k]` with the softmax over the 9 taps of subpixel `s` of every
/// pixel `x` of coarse row `y`, from one image's mask (`[9·ff][H][W]`, tap-major).
pub(crate) fn softmax_weights(weights: &mut Vec<f32>, mask: &[f32], [h, w]: [usize; 2], y: usize, ff: usize) {
    weights.resize(w * ff * 9, 0.0);
    let plane = h * w;
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
}

/// The 3x3 neighbourhood of `(y, x)` in one channel plane, zero outside, times `factor`.
pub(crate) fn neighbourhood(flow: &[f32], [h, w]: [usize; 2], y: usize, x: usize, factor: usize) -> [f32; 9] {
    std::array::from_fn(|k| {
        let (yy, xx) = (y + k / 3, x + k % 3);
        let inside = (1..=h).contains(&yy) && (1..=w).contains(&xx);
        if inside { flow[(yy - 1) * w + xx - 1] * factor as f32 } else { 0.0 }
    })
}
