//! The correlation volume's product in bf16 with f32 sums (CPU inference with bf16 products):
//! per image row, `fmap1`'s `W1 x C` against `fmap2`'s `C x W2`, read where the feature maps
//! lie (NCHW) without a transpose of the maps.

use dgstereo_core::tensor::zeros_parallel;
use rayon::prelude::*;

use crate::bf16_product::{Bf16Unit, PackedWeights, matmul_bf16};

/// `corr[n, y, x1, x2] = <fmap1[n, :, y, x1], fmap2[n, :, y, x2]> / sqrt(C)` as the rows
/// `[N·H·W1, W2]`, the products in bf16 on `unit`.
///
/// # Shapes
/// - `fmap1`: `[N, C, H, W1]` (`dims`); `fmap2`: `[N, C, H, W2]`
pub(crate) fn all_pairs_bf16(
    fmap1: &[f32],
    fmap2: &[f32],
    [n, c, h, w1]: [usize; 4],
    w2: usize,
    unit: Bf16Unit,
) -> Vec<f32> {
    assert_eq!(fmap1.len(), n * c * h * w1, "all pairs: fmap1 does not match [{n}, {c}, {h}, {w1}]");
    assert_eq!(fmap2.len(), n * c * h * w2, "all pairs: fmap2 does not match [{n}, {c}, {h}, {w2}]");
    let scale = 1.0 / (c as f32).sqrt();
    let mut out = zeros_parallel(n * h * w1 * w2);
    if w1 * w2 == 0 {
        return out;
    }
    out.par_chunks_mut(w1 * w2).enumerate().for_each(|(row, dst)| {
        let (b, y) = (row / h, row % h);
        // Channel `ch` of the row starts at `ch·H·W`: the left operand stored column by column,
        // the right one row by row, both with the row stride `H·W`.
        let lhs = PackedWeights::from_columns(&fmap1[b * c * h * w1 + y * w1..], h * w1, [w1, c]);
        let rhs = &fmap2[b * c * h * w2 + y * w2..];
        matmul_bf16(unit, dst, w2, &lhs, rhs, h * w2, w2, false);
        dst.iter_mut().for_each(|v| *v *= scale);
    });
    out
}
