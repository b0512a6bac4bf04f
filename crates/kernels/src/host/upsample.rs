//! Convex upsampling on the host: one parallel sweep that computes each coarse pixel's softmax
//! weights once and writes its `factor x factor` block of every channel.

use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::{host_values, zeros_parallel};
use rayon::prelude::*;

/// Convex upsampling (`crate::ops::upsample::convex_upsample`) on the host: per image and coarse row, the softmax weights of the row's
/// pixels (`[W][factor²][9]`), then the `factor` output rows of every channel.
///
/// # Panics
/// When `mask` does not have `9·factor²` channels of `flow`'s batch and size.
pub fn convex_upsample_host(flow: Tensor<4>, mask: Tensor<4>, factor: usize) -> Tensor<4> {
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
