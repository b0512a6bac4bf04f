//! The pyramid lookup as one hand-written loop over host memory (inference on the CPU).
//!
//! The stock lookup (`crate::ops::lookup`) composes about twenty tensor operations per level
//! (floor, offsets, masks, clamp, gather, two slices, interpolation, concatenation, permute),
//! each a pass over `[H·W, 2r+2]` data with its own allocation; on the CPU the work itself is a
//! few hundred thousand multiply-adds. This kernel does the same arithmetic, in the same order
//! (so results agree to the last bit in practice, and are tested to agree within 1e-5), in one
//! pass per output plane, reading the pyramid where the build left it on the host. It has no
//! gradient, so the pyramid uses it only when its device is the CPU backend without autodiff;
//! training keeps the stock path.

use std::sync::Arc;

use dgstereo_core::tensor::{planes_from, zeros_parallel};
use rayon::prelude::*;

/// One pyramid level on the host: `rows` rows of `width` correlations.
#[derive(Debug, Clone)]
pub struct HostLevel {
    /// Row-major `[rows, width]`.
    pub values: Arc<[f32]>,
    /// Entries per row (`W2 / 2^level`).
    pub width: usize,
}

/// Averages neighbouring pairs of each row (dropping an odd last column), as the stock
/// `mean_dim` pooling: `(a + b) / 2`.
pub fn pool_rows(level: &HostLevel, rows: usize) -> HostLevel {
    let half = level.width / 2;
    let mut out = Vec::with_capacity(rows * half);
    for row in level.values.chunks_exact(level.width.max(1)).take(rows) {
        out.extend((0..half).map(|j| (row[2 * j] + row[2 * j + 1]) / 2.0));
    }
    if half == 0 {
        out.clear();
    }
    HostLevel { values: out.into(), width: half }
}

/// Samples `levels` at `coords / 2^level + dx`, `dx = -radius..=radius`, by linear
/// interpolation with zeros outside each row.
///
/// # Shapes
/// - `levels[i].values`: `[N·H·W1, width_i]`; `coords`: `[N·H·W1]` in (n, h, x) order
/// - output: `[N, levels·(2r+1), H, W1]` row-major, level-major then offset
pub fn lookup(levels: &[HostLevel], coords: &[f32], [n, h, w1]: [usize; 3], radius: usize) -> Vec<f32> {
    let k = 2 * radius + 1;
    let plane = h * w1;
    let channels = levels.len() * k;
    if channels == 0 || plane == 0 {
        return Vec::new();
    }
    // Pixel-major first, so each pixel's pyramid rows are read once for all their taps (the
    // rows do not fit in cache; plane by plane they were re-read `2r + 1` times).
    let mut by_pixel = zeros_parallel(n * plane * channels);
    by_pixel.par_chunks_mut(channels * w1.max(1)).enumerate().for_each(|(chunk, dst)| {
        for (i, out) in dst.chunks_exact_mut(channels).enumerate() {
            let m = chunk * w1 + i;
            for (level, HostLevel { values, width }) in levels.iter().enumerate() {
                let width = *width;
                if width == 0 {
                    continue;
                }
                let x = coords[m] / (1u64 << level) as f32;
                let x0 = x.floor();
                let w = x - x0;
                let row = &values[m * width..(m + 1) * width];
                let last = (width - 1) as f32;
                let at = |pos: f32| if (0.0..=last).contains(&pos) { row[pos as usize] } else { 0.0 };
                for (t, d) in out[level * k..(level + 1) * k].iter_mut().enumerate() {
                    let pos = x0 + (t as f32 - radius as f32);
                    *d = at(pos) * (-w + 1.0) + at(pos + 1.0) * w;
                }
            }
        }
    });
    pixels_to_planes(&by_pixel, n, plane, channels)
}

/// Transposes pixel-major lookups into channel planes.
///
/// # Shapes
/// - `by_pixel`: `[N, plane, channels]` row-major; output `[N, channels, plane]`
pub(crate) fn pixels_to_planes(by_pixel: &[f32], n: usize, plane: usize, channels: usize) -> Vec<f32> {
    planes_from(n * channels, plane, |p| {
        let (b, c) = (p / channels, p % channels);
        let src = &by_pixel[b * plane * channels..(b + 1) * plane * channels];
        (0..plane).map(move |j| src[j * channels + c])
    })
}
