//! A linear layer's product in bf16 with f32 sums (CPU inference with bf16 products): the rows of
//! `x` (`rows x d_in`) against the weight (`d_in x d_out`, burn's `Linear` layout), in blocks of
//! rows, one block per job.
//!
//! The rows are the product's left operand, packed to bf16 per block; the weight is the right
//! operand, converted into pairs at each block's product. A block of `BLOCK_ROWS` rows or more
//! keeps that conversion (`d_in · d_out` values) to a small share of the block's
//! `rows · d_in · d_out` products; the ViT's projections have 1,300-2,600 rows per view pair at
//! DEFOM-Stereo's sizes, a few blocks per core.

use dgstereo_core::tensor::zeros_parallel;
use rayon::prelude::*;

use crate::bf16_product::{Bf16Unit, PackedWeights, matmul_bf16};

/// The fewest rows of a job's block (but the last).
const BLOCK_ROWS: usize = 128;

/// `x · weight + bias` for `x` of `rows x d_in` and `weight` of `d_in x d_out` (row-major), the
/// products in bf16 on `unit`; `rows x d_out` row-major.
pub(crate) fn linear_bf16(
    x: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
    [rows, d_in, d_out]: [usize; 3],
    unit: Bf16Unit,
) -> Vec<f32> {
    assert_eq!(x.len(), rows * d_in, "linear: the input does not hold {rows} rows of {d_in}");
    assert_eq!(weight.len(), d_in * d_out, "linear: the weight is not {d_in} x {d_out}");
    assert!(bias.is_none_or(|b| b.len() == d_out), "linear: the bias is not {d_out} long");
    let mut out = zeros_parallel(rows * d_out);
    if rows * d_out == 0 {
        return out;
    }
    let jobs = rayon::current_num_threads().max(1) * 2;
    let block = rows.div_ceil(jobs).max(BLOCK_ROWS);
    out.par_chunks_mut(block * d_out).enumerate().for_each(|(j, dst)| {
        let r0 = j * block;
        let n = dst.len() / d_out;
        let lhs = PackedWeights::new(&x[r0 * d_in..], d_in, [n, d_in]);
        matmul_bf16(unit, dst, d_out, &lhs, weight, d_out, d_out, false);
        if let Some(bias) = bias {
            dst.chunks_mut(d_out).for_each(|row| row.iter_mut().zip(bias).for_each(|(v, b)| *v += b));
        }
    });
    out
}
