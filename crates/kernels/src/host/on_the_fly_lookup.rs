//! The on-the-fly ("alt") lookup as one hand-written loop over host memory (inference on the CPU).
//!
//! The stock lookup (`crate::ops::lookup::OnTheFlyCorrelation` on tensors) gathers, for every level and
//! every one of the `2r + 2` taps, a copy of the right features the size of the left map
//! (`[N, C, H, W1]`), multiplies it with the left map and reduces over `C`, then adds the
//! tap/mask/interpolation operations: about `levels · (2r + 2)` full passes with their own
//! allocations, seconds per lookup at 1/4 of a 320x736 image. The arithmetic itself is
//! `levels · (2r + 2) · C` multiply-adds per pixel.
//!
//! Design: the features are laid out channel-last on the host once, when the volume is built
//! ([`ChannelLastFeatures`], pooled levels included), so every correlation is the dot product
//! of two contiguous `C`-slices. The lookup is one pass per image row (rows in parallel), which
//! keeps that row's pooled right features in cache for the whole left row. Taps, weights and
//! the zero-outside rule are those of the stock path ([`crate::lookup`]), in the same order;
//! only the summation order inside a dot product differs from burn's, so the two agree to float
//! rounding (tested within 1e-5 of the largest correlation). There is no gradient: the volume
//! uses this kernel only where the dispatch picks the host path.

use std::sync::Arc;

use rayon::prelude::*;

use super::pyramid_lookup::pixels_to_planes;

/// Features of one side on the host, channel-last so each pixel's channels are contiguous.
#[derive(Debug, Clone)]
pub struct ChannelLastFeatures {
    /// Row-major `[N, H, W, C]`.
    pub values: Arc<[f32]>,
    /// `[N, H, W, C]`.
    pub dims: [usize; 4],
}

impl ChannelLastFeatures {
    /// Transposes channel-first features.
    ///
    /// # Shapes
    /// - `values`: `[N, C, H, W]` row-major, `[n, c, h, w]` = `dims`; result `[N, H, W, C]`
    pub fn from_channel_first(values: &[f32], [n, c, h, w]: [usize; 4]) -> Self {
        assert_eq!(
            values.len(),
            n * c * h * w,
            "features hold {} values, not N·C·H·W of {:?}",
            values.len(),
            [n, c, h, w]
        );
        let mut out = vec![0f32; values.len()];
        if c > 0 && w > 0 {
            out.par_chunks_mut(w * c).enumerate().for_each(|(row, dst)| {
                let (b, y) = (row / h, row % h);
                for (ch, plane) in values[b * c * h * w..(b + 1) * c * h * w].chunks_exact(h * w).enumerate() {
                    for (x, &v) in plane[y * w..(y + 1) * w].iter().enumerate() {
                        dst[x * c + ch] = v;
                    }
                }
            });
        }
        Self { values: out.into(), dims: [n, h, w, c] }
    }

    /// The next pyramid level: neighbouring columns averaged, `(a + b) / 2`, an odd last column
    /// dropped (the stock `avg_pool2d([1, 2])`); a width below 2 gives width 0.
    ///
    /// # Shapes
    /// - `[N, H, W, C]` -> `[N, H, W / 2, C]`
    pub fn pool_columns(&self) -> Self {
        let [n, h, w, c] = self.dims;
        let half = w / 2;
        let mut out = vec![0f32; n * h * half * c];
        if half > 0 && c > 0 {
            out.par_chunks_mut(half * c).zip(self.values.par_chunks(w * c)).for_each(|(dst, row)| {
                for (j, d) in dst.chunks_exact_mut(c).enumerate() {
                    let (a, b) = (&row[2 * j * c..(2 * j + 1) * c], &row[(2 * j + 1) * c..(2 * j + 2) * c]);
                    for ((d, a), b) in d.iter_mut().zip(a).zip(b) {
                        *d = (a + b) / 2.0;
                    }
                }
            });
        }
        Self { values: out.into(), dims: [n, h, half, c] }
    }
}

/// Correlates `fmap1` with each level of `pooled` at `coords / 2^level + dx`,
/// `dx = -radius..=radius`, by linear interpolation between the dot products at the `2r + 2`
/// integer taps, zero outside each row, scaled by `1 / sqrt(C)`.
///
/// # Shapes
/// - `fmap1`: `[N, H, W1, C]`; `pooled[i]`: `[N, H, W2 / 2^i, C]`
/// - `coords`: `[N·H·W1]` in (n, h, x) order
/// - output: `[N, levels·(2r+1), H, W1]` row-major, level-major then offset
pub fn lookup(fmap1: &ChannelLastFeatures, pooled: &[ChannelLastFeatures], coords: &[f32], radius: usize) -> Vec<f32> {
    let [n, h, w1, c] = fmap1.dims;
    for (level, f2) in pooled.iter().enumerate() {
        let [n2, h2, _, c2] = f2.dims;
        assert!(
            [n2, h2, c2] == [n, h, c],
            "level {level} of the right features is {:?}, the left features {:?} (N, H, W, C)",
            f2.dims,
            fmap1.dims
        );
    }
    assert_eq!(coords.len(), n * h * w1, "{} coordinates for {n}x{h}x{w1} left pixels", coords.len());
    let k = 2 * radius + 1;
    let plane = h * w1;
    let channels = pooled.len() * k;
    if channels == 0 || plane == 0 || n == 0 {
        return vec![0f32; n * channels * plane];
    }
    let scale = (c as f64).sqrt() as f32;
    let offset = |t: usize| t as f32 - radius as f32;
    let mut by_pixel = vec![0f32; n * plane * channels];
    by_pixel.par_chunks_mut(w1 * channels).enumerate().for_each(|(row, dst)| {
        let mut taps = vec![0f32; k + 1];
        for (x, out) in dst.chunks_exact_mut(channels).enumerate() {
            let m = row * w1 + x;
            let left = &fmap1.values[m * c..(m + 1) * c];
            for (level, f2) in pooled.iter().enumerate() {
                let width = f2.dims[2];
                if width == 0 {
                    continue;
                }
                let right = &f2.values[row * width * c..(row + 1) * width * c];
                let xi = coords[m] / (1u64 << level) as f32;
                let x0 = xi.floor();
                let w = xi - x0;
                let last = (width - 1) as f32;
                for (t, v) in taps.iter_mut().enumerate() {
                    let pos = x0 + offset(t);
                    *v = if (0.0..=last).contains(&pos) {
                        let p = pos as usize;
                        dot(left, &right[p * c..(p + 1) * c]) / scale
                    } else {
                        0.0
                    };
                }
                for (t, d) in out[level * k..(level + 1) * k].iter_mut().enumerate() {
                    *d = taps[t] * (-w + 1.0) + taps[t + 1] * w;
                }
            }
        }
    });
    pixels_to_planes(&by_pixel, n, plane, channels)
}

/// `<a, b>` with independent partial sums (so the compiler can keep them in vector registers).
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    const LANES: usize = 16;
    let (a_chunks, a_rest) = a.as_chunks::<LANES>();
    let (b_chunks, b_rest) = b.as_chunks::<LANES>();
    let mut acc = [0f32; LANES];
    for (x, y) in a_chunks.iter().zip(b_chunks) {
        for l in 0..LANES {
            acc[l] += x[l] * y[l];
        }
    }
    let rest: f32 = a_rest.iter().zip(b_rest).map(|(x, y)| x * y).sum();
    acc.iter().sum::<f32>() + rest
}
