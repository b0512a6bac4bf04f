//! The pyramid lookup as one hand-written loop over host memory (inference on the CPU).
//!
//! The stock lookup ([`crate::lookup`]) composes about twenty tensor operations per level
//! (floor, offsets, masks, clamp, gather, two slices, interpolation, concatenation, permute),
//! each a pass over `[H·W, 2r+2]` data with its own allocation; on the CPU the work itself is a
//! few hundred thousand multiply-adds. This kernel does the same arithmetic, in the same order
//! (so results agree to the last bit in practice, and are tested to agree within 1e-5), in one
//! pass per output plane, reading the pyramid where the build left it on the host. It has no
//! gradient, so the pyramid uses it only when its device is the CPU backend without autodiff;
//! training keeps the stock path.

use std::sync::Arc;

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
    let planes = levels.len() * k;
    let mut out = vec![0f32; n * planes * plane];
    out.par_chunks_mut(plane).enumerate().for_each(|(p, dst)| {
        let (b, c) = (p / planes, p % planes);
        let (level, t) = (c / k, c % k);
        let HostLevel { values, width } = &levels[level];
        let width = *width;
        if width == 0 {
            return;
        }
        let scale = (1u64 << level) as f32;
        let offset = t as f32 - radius as f32;
        let last = (width - 1) as f32;
        let base = b * plane;
        for (j, d) in dst.iter_mut().enumerate() {
            let m = base + j;
            let x = coords[m] / scale;
            let x0 = x.floor();
            let w = x - x0;
            let row = &values[m * width..(m + 1) * width];
            let at = |pos: f32| if (0.0..=last).contains(&pos) { row[pos as usize] } else { 0.0 };
            let lo = at(x0 + offset);
            let hi = at(x0 + offset + 1.0);
            *d = lo * (-w + 1.0) + hi * w;
        }
    });
    out
}
