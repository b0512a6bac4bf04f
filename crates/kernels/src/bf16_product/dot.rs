//! The AVX512-BF16 kernel (`vdpbf16ps`: 16 f32 sums a vector, each adding the products of one
//! pair) and the vectorised conversion of a column matrix into pairs.
//!
//! The kernel keeps [`ROWS`] rows by 32 columns of sums in 24 vector registers; a step over one
//! pair of the depth loads two vectors of pairs (32 columns) and broadcasts one pair of each
//! row's weights, for 24 `vdpbf16ps` (768 multiply-adds). The loop order: a column block of the
//! pairs (`depth x 32`, in the core's L2 cache even for the GRUs' depth of 3456) outside, the
//! weights' row blocks inside.

use std::arch::x86_64::*;

use super::features::Bf16Unit;
use super::operands::{COL_STEP, Operands};

/// Rows of sums the kernel keeps.
const ROWS: usize = 12;

/// [`super::pack_pairs`] by vectors: rows `2·kp` and `2·kp + 1` of `rhs` converted together
/// (`vcvtne2ps2bf16`) and interleaved (`vpermw`), 16 columns a step, masked at the end of a row.
pub(super) fn pack_pairs(pairs: &mut [u16], rhs: &[f32], stride: usize, [depth, cols]: [usize; 2], cols_pad: usize) {
    assert!(cols <= cols_pad && cols_pad.is_multiple_of(COL_STEP));
    assert!(pairs.len() >= depth.div_ceil(2) * cols_pad * 2);
    assert!(depth == 0 || rhs.len() >= (depth - 1) * stride + cols);
    assert!(Bf16Unit::DotProducts.available());
    // SAFETY: the processor has the instructions (asserted); the asserts keep every load inside
    // `rhs` (row `k < depth`, columns below `cols` by the masks) and every store inside `pairs`.
    unsafe { pack_pairs_avx512(pairs, rhs, stride, [depth, cols], cols_pad) }
}

#[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
unsafe fn pack_pairs_avx512(pairs: &mut [u16], rhs: &[f32], stride: usize, [depth, cols]: [usize; 2], cols_pad: usize) {
    // Lane 2i takes value i of the first row, lane 2i + 1 value i of the second: the converted
    // vector holds the first row's 16 values in its low half and the second's in its high half.
    let interleave = _mm512_set_epi16(
        31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17, 1,
        16, 0,
    );
    for kp in 0..depth.div_ceil(2) {
        let (first, second) = (2 * kp, 2 * kp + 1);
        for j in (0..cols).step_by(16) {
            let mask: __mmask16 = if cols - j >= 16 { 0xffff } else { (1u16 << (cols - j)) - 1 };
            // SAFETY (all loads and stores below): the caller's asserts (see `pack_pairs`).
            let a = unsafe { _mm512_maskz_loadu_ps(mask, rhs.as_ptr().add(first * stride + j)) };
            let b = if second < depth {
                unsafe { _mm512_maskz_loadu_ps(mask, rhs.as_ptr().add(second * stride + j)) }
            } else {
                _mm512_setzero_ps()
            };
            // SAFETY: both types are 64 bytes of lanes; the bits are reinterpreted as 32 words.
            let converted: __m512i = unsafe { std::mem::transmute(_mm512_cvtne2ps_pbh(b, a)) };
            let paired = _mm512_permutexvar_epi16(interleave, converted);
            unsafe { _mm512_storeu_si512(pairs.as_mut_ptr().add((kp * cols_pad + j) * 2).cast(), paired) };
        }
    }
}

/// `dst (+)= lhs · rhs` from the packed operands on the calling thread.
pub(super) fn product(dst: &mut [f32], dst_stride: usize, operands: &Operands, accumulate: bool) {
    let Operands { lhs, pairs, cols, cols_pad } = *operands;
    let rows = lhs.rows;
    assert!(pairs.len() >= lhs.depth_pad * cols_pad && lhs.values.len() >= rows * lhs.depth_pad);
    assert!(rows == 0 || cols == 0 || dst.len() >= (rows - 1) * dst_stride + cols);
    assert!(Bf16Unit::DotProducts.available());
    for j in (0..cols).step_by(COL_STEP) {
        let width = (cols - j).min(COL_STEP);
        for r in (0..rows).step_by(ROWS) {
            let block = Block {
                dst: dst[r * dst_stride + j..].as_mut_ptr(),
                dst_stride,
                lhs: lhs.values[r * lhs.depth_pad..].as_ptr(),
                lhs_stride: lhs.depth_pad,
                pairs: pairs[j * 2..].as_ptr(),
                cols_pad,
                depth_pairs: lhs.depth.div_ceil(2),
                width,
                accumulate,
            };
            // SAFETY: the processor has the instructions (asserted); the block reads rows
            // `r..r + n` of the weights (`n <= rows - r`) up to `depth_pairs` pairs, the pairs'
            // columns `j..j + 32` of each pair row (`cols_pad` is a multiple of 32), and writes
            // `width` columns of `n` rows of `dst`, all inside the asserted lengths.
            unsafe {
                match (rows - r).min(ROWS) {
                    12 => block.run::<12>(),
                    11 => block.run::<11>(),
                    10 => block.run::<10>(),
                    9 => block.run::<9>(),
                    8 => block.run::<8>(),
                    7 => block.run::<7>(),
                    6 => block.run::<6>(),
                    5 => block.run::<5>(),
                    4 => block.run::<4>(),
                    3 => block.run::<3>(),
                    2 => block.run::<2>(),
                    _ => block.run::<1>(),
                }
            }
        }
    }
}

/// One block of sums: up to [`ROWS`] rows by 32 columns, over the whole depth.
struct Block {
    dst: *mut f32,
    dst_stride: usize,
    lhs: *const u16,
    lhs_stride: usize,
    pairs: *const u16,
    cols_pad: usize,
    depth_pairs: usize,
    /// Columns of `dst` written (at most 32).
    width: usize,
    accumulate: bool,
}

impl Block {
    /// The block's `R` rows of sums.
    ///
    /// # Safety
    /// The processor has AVX512-BF16, and the pointers reach `R` rows of `depth_pairs` weight
    /// pairs, `depth_pairs` pair rows of 32 columns and `R` rows of `width` outputs.
    #[target_feature(enable = "avx512f,avx512bf16")]
    #[allow(clippy::needless_range_loop)] // indices keep `sums` in registers (below)
    unsafe fn run<const R: usize>(&self) {
        // Index loops over constant bounds only: no iterator adapter or closure touches `sums`,
        // so the compiler keeps it in registers (with them it kept a copy on the stack and
        // stored every sum at every step, halving the kernel's rate).
        let mut sums = [[_mm512_setzero_ps(); 2]; R];
        let mut b = self.pairs;
        for kp in 0..self.depth_pairs {
            // SAFETY (the loads): the contract of `run`.
            let (b0, b1): (__m512bh, __m512bh) = unsafe {
                (
                    std::mem::transmute::<__m512i, __m512bh>(_mm512_loadu_si512(b.cast())),
                    std::mem::transmute::<__m512i, __m512bh>(_mm512_loadu_si512(b.add(32).cast())),
                )
            };
            let mut a_row = unsafe { self.lhs.add(2 * kp) };
            for r in 0..R {
                // SAFETY: 64 bytes of lanes reinterpreted as 32 bf16 values (16 copies of the
                // row's pair); the load is inside the row (the contract of `run`).
                let a = unsafe {
                    std::mem::transmute::<__m512i, __m512bh>(_mm512_set1_epi32(a_row.cast::<i32>().read_unaligned()))
                };
                sums[r][0] = _mm512_dpbf16_ps(sums[r][0], a, b0);
                sums[r][1] = _mm512_dpbf16_ps(sums[r][1], a, b1);
                a_row = unsafe { a_row.add(self.lhs_stride) };
            }
            b = unsafe { b.add(self.cols_pad * 2) };
        }
        let mut masks: [__mmask16; 2] = [0; 2];
        for (half, mask) in [0usize, 16].into_iter().zip(&mut masks) {
            let w = self.width.saturating_sub(half);
            *mask = if w >= 16 { 0xffff } else { ((1u32 << w) - 1) as u16 };
        }
        for r in 0..R {
            for half in 0..2 {
                // SAFETY: the masks keep the accesses inside the row's `width` outputs.
                unsafe {
                    let out = self.dst.add(r * self.dst_stride + 16 * half);
                    let sum = sums[r][half];
                    let value =
                        if self.accumulate { _mm512_add_ps(sum, _mm512_maskz_loadu_ps(masks[half], out)) } else { sum };
                    _mm512_mask_storeu_ps(out, masks[half], value);
                }
            }
        }
    }
}
