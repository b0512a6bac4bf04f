//! The left operands of a Winograd convolution's `α²` products, in the precision of its
//! products: the weights' transform in f32, or packed in bf16 per position of the tile.

use std::ops::Range;
use std::sync::Arc;

use super::transforms::Variant;
use super::weight_cache::{packed_positions, transformed_weights};
use crate::bf16_product::{Bf16Unit, PackedWeights, matmul_bf16};
use crate::product::matmul_strided_with;

/// `U_k` over a range of input channels for each position `k` of the transformed tile.
pub(crate) enum Positions {
    /// The transform `[O][α²][C]` in f32, products by the `gemm` crate.
    F32 {
        /// The whole transform.
        u: Arc<Vec<f32>>,
        /// Output channels.
        o: usize,
        /// Input channels of the transform (the row stride is `α²·c`).
        c: usize,
        /// The input channels the products take.
        channels: Range<usize>,
    },
    /// Per position, `O x channels` in bf16, products on the unit with f32 sums.
    Bf16(Bf16Unit, Arc<Vec<PackedWeights>>),
}

impl Positions {
    /// The operands of `wt` (`[O, C, 3, 3]`) for `variant` over input channels `channels`, in
    /// bf16 on `unit` where it is given; both kept between calls in an open
    /// [`super::UpdateLoop`] scope.
    pub(crate) fn new(
        variant: &Variant,
        wt: &[f32],
        [o, c]: [usize; 2],
        channels: Range<usize>,
        unit: Option<Bf16Unit>,
    ) -> Self {
        match unit {
            Some(unit) => Self::Bf16(unit, packed_positions(variant, wt, o, c, channels, unit)),
            None => Self::F32 { u: transformed_weights(variant, wt, o, c), o, c, channels },
        }
    }

    /// `dst (+)= U_k · rhs` of position `k` of `k2`: `dst` `O x t` (row stride `dst_stride`),
    /// `rhs` `channels x t` (row stride `rhs_stride`); added to `dst` when `accumulate`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn product(
        &self,
        [k, k2]: [usize; 2],
        dst: &mut [f32],
        dst_stride: usize,
        rhs: &[f32],
        rhs_stride: usize,
        t: usize,
        accumulate: bool,
    ) {
        match self {
            Self::F32 { u, o, c, channels } => {
                let lhs = &u[k * c + channels.start..];
                let dims = [*o, t, channels.len()];
                matmul_strided_with(dst, dst_stride, lhs, k2 * c, rhs, rhs_stride, dims, accumulate);
            }
            Self::Bf16(unit, positions) => {
                matmul_bf16(*unit, dst, dst_stride, &positions[k], rhs, rhs_stride, t, accumulate);
            }
        }
    }
}
