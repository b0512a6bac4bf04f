//! The gradients of convex upsampling on host buffers, for training on the CPU.
//!
//! Design decision: burn's autodiff of the stock composition (softmax over a reshaped mask,
//! `unfold`, a broadcast product, a sum and a permute) ran its forward and backward mostly on the
//! calling thread, about 5 % of the main thread's samples in a training step. Here the forward is
//! the inference pass, keeping its softmax weights
//! ([`super::upsample::convex_upsample_values_keeping_weights`]), and the backward two parallel
//! sweeps: per (image, coarse row) the mask's gradient from those weights and each tap's
//! gradient `dT`; then per (image, channel, row) the flow's gradient, gathered from the `dT` of
//! the 9 coarse pixels that read it (a gather, so no two tasks write one value).

use dgstereo_core::tensor::zeros_parallel;
use rayon::prelude::*;

use super::upsample::neighbourhood;
use crate::geometry::band_jobs;

/// The gradients of [`super::upsample::convex_upsample_values`] with respect to `flow` and `mask`,
/// given the output gradient `g` and the forward's softmax weights `weights`
/// ([`super::upsample::convex_upsample_values_keeping_weights`]).
///
/// With `W[s][k]` the softmax over the 9 taps of subpixel `s`, `T[k]` the tap's value times
/// `factor` and `G[s]` the output gradient: `dW[s][k] = Σ_c G_c[s]·T_c[k]`, `dmask[k][s] =
/// W[s][k]·(dW[s][k] − Σ_k' W[s][k']·dW[s][k'])` and `dT_c[k] = Σ_s W[s][k]·G_c[s]`, which goes to
/// the flow at the tap's position times `factor`.
///
/// # Shapes
/// - `flow`: `dims = [N, D, H, W]`; `weights`: `[N][H][W][factor²][9]`; `g`: `[N, D, factor·H,
///   factor·W]`; returns `(dflow, dmask)`, `dmask` of the mask's shape `[N, 9·factor², H, W]`
pub fn convex_upsample_backward(
    flow: &[f32],
    weights: &[f32],
    g: &[f32],
    dims: [usize; 4],
    factor: usize,
) -> (Vec<f32>, Vec<f32>) {
    let [n, d, h, w] = dims;
    let (ff, plane, wide) = (factor * factor, h * w, factor * w);
    assert_eq!(
        g.len(),
        n * d * plane * ff,
        "convex_upsample_backward: the gradient is not [{n}, {d}, {}, {wide}]",
        factor * h
    );
    assert_eq!(
        weights.len(),
        n * 9 * ff * plane,
        "convex_upsample_backward: the weights are not [{n}][{h}][{w}][{ff}][9]"
    );
    let mut dmask = zeros_parallel(n * 9 * ff * plane);
    // dT[((b·D + c)·H + y)·W·9 + x·9 + k].
    let mut dtaps = zeros_parallel(n * d * plane * 9);
    // One job per (image, coarse row): its row of each of the 9·ff mask planes and of each
    // channel's taps.
    let mask_jobs = band_jobs(&mut dmask, 9 * ff, plane, w.max(1));
    let tap_jobs = band_jobs(&mut dtaps, d, plane * 9, (9 * w).max(1));
    let jobs = mask_jobs.into_par_iter().zip(tap_jobs);
    jobs.enumerate().for_each(|(job, (mut mask_rows, mut tap_rows))| {
        let (b, y) = (job / h, job % h);
        let weights = &weights[(b * h + y) * w * ff * 9..][..w * ff * 9];
        let (mut taps, mut grads) = (vec![[0.0f32; 9]; d], vec![0.0f32; d]);
        for x in 0..w {
            for (c, t) in taps.iter_mut().enumerate() {
                *t = neighbourhood(&flow[(b * d + c) * plane..][..plane], [h, w], y, x, factor);
            }
            for s in 0..ff {
                let (oy, ox) = (y * factor + s / factor, x * factor + s % factor);
                for (c, v) in grads.iter_mut().enumerate() {
                    *v = g[((b * d + c) * factor * h + oy) * wide + ox];
                }
                let weight = &weights[(x * ff + s) * 9..][..9];
                let dw: [f32; 9] = std::array::from_fn(|k| (0..d).map(|c| grads[c] * taps[c][k]).sum());
                let mean: f32 = weight.iter().zip(&dw).map(|(a, b)| a * b).sum();
                for k in 0..9 {
                    mask_rows[k * ff + s][x] = weight[k] * (dw[k] - mean);
                    for (c, rows) in tap_rows.iter_mut().enumerate() {
                        rows[x * 9 + k] += weight[k] * grads[c];
                    }
                }
            }
        }
    });
    // dflow[b][c][y'][x'] = factor · Σ_k dT at the coarse pixel whose tap k reads (y', x').
    let mut dflow = zeros_parallel(n * d * plane);
    dflow.par_chunks_mut(w.max(1)).enumerate().for_each(|(i, row)| {
        let (bc, yy) = (i / h, i % h);
        let dtaps = &dtaps[bc * plane * 9..][..plane * 9];
        for (xx, value) in row.iter_mut().enumerate() {
            let mut sum = 0.0f32;
            for k in 0..9 {
                // Tap k of pixel (y, x) reads (y + k/3 - 1, x + k%3 - 1).
                let (y, x) = ((yy + 1).checked_sub(k / 3), (xx + 1).checked_sub(k % 3));
                if let (Some(y), Some(x)) = (y, x)
                    && y < h
                    && x < w
                {
                    sum += dtaps[(y * w + x) * 9 + k];
                }
            }
            *value = factor as f32 * sum;
        }
    });
    (dflow, dmask)
}
