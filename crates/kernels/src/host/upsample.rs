//! Convex upsampling on the host: one parallel sweep that computes each coarse pixel's softmax
//! weights once and writes its `factor x factor` block of every channel; in training it keeps
//! the weights for the backward.

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
pub fn convex_upsample_values(flow: &[f32], mask: &[f32], dims: [usize; 4], factor: usize) -> Vec<f32> {
    upsample(flow, mask, dims, factor, None)
}

/// [`convex_upsample_values`] that also returns the softmax weights it computed,
/// `[N][H][W][factor²][9]`: the training forward keeps them for the backward
/// (`crate::host::upsample_backward`), which then needs no softmax of its own.
///
/// # Panics
/// As [`convex_upsample_values`].
pub fn convex_upsample_values_keeping_weights(
    flow: &[f32],
    mask: &[f32],
    dims: [usize; 4],
    factor: usize,
) -> (Vec<f32>, Vec<f32>) {
    let mut weights = zeros_parallel(mask.len());
    let out = upsample(flow, mask, dims, factor, Some(&mut weights));
    (out, weights)
}

/// The sweep of both: per image and coarse row, the softmax weights of the row's pixels
/// (`[W][factor²][9]`, into `kept`'s row where given, else a scratch buffer), then the `factor`
/// output rows of every channel.
fn upsample(flow: &[f32], mask: &[f32], [n, d, h, w]: [usize; 4], factor: usize, kept: Option<&mut [f32]>) -> Vec<f32> {
    let ff = factor * factor;
    let plane = h * w;
    assert_eq!(flow.len(), n * d * plane, "convex_upsample: the flow is not [{n}, {d}, {h}, {w}]");
    assert_eq!(mask.len(), n * 9 * ff * plane, "convex_upsample: the mask is not [{n}, {}, {h}, {w}]", 9 * ff);
    let wide = factor * w;
    let mut out = zeros_parallel(n * d * plane * ff);
    // One job per (image, coarse row): its `factor` output rows in each of the `d` channels.
    let jobs = band_jobs(&mut out, d, plane * ff, (factor * wide).max(1));
    let kept_rows: Vec<Option<&mut [f32]>> = match kept {
        Some(kept) => kept.chunks_mut((w * ff * 9).max(1)).map(Some).collect(),
        None => (0..n * h).map(|_| None).collect(),
    };
    jobs.into_par_iter().zip(kept_rows).enumerate().for_each_init(Vec::new, |scratch, (job, (mut rows, kept))| {
        let (b, y) = (job / h, job % h);
        let mask = &mask[b * 9 * ff * plane..][..9 * ff * plane];
        let weights: &[f32] = match kept {
            Some(kept) => {
                softmax_into(kept, mask, [h, w], y, ff);
                kept
            }
            None => {
                scratch.resize(w * ff * 9, 0.0);
                softmax_into(scratch, mask, [h, w], y, ff);
                scratch
            }
        };
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

/// Fills `weights[(x·ff + s)·9 + k]` (`W·ff·9` values) with the softmax over the 9 taps of
/// subpixel `s` of every pixel `x` of coarse row `y`, from one image's mask (`[9·ff][H][W]`,
/// tap-major).
fn softmax_into(weights: &mut [f32], mask: &[f32], [h, w]: [usize; 2], y: usize, ff: usize) {
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
