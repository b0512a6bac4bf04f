//! Matrix products with bf16 inputs and f32 sums on the processor's matrix units: AMX tiles
//! (`tdpbf16ps`) where the processor has them, else AVX512-BF16's `vdpbf16ps`.
//!
//! Design decision: no crate does this product (the `gemm` crate has f32, f64 and f16 but no bf16
//! path; oneDNN's bindings bring a C++ library and its build), so the two kernels are ours, each
//! one loop over the products' depth. Both read the same two layouts:
//! - the left operand (a layer's weight, `rows x depth`) is converted once into
//!   [`PackedWeights`]: bf16, row-major, the depth padded to a multiple of `DEPTH_STEP` and the
//!   rows to a multiple of `ROW_STEP` with zeros. An AMX tile loads 16 of its rows of 32 values
//!   at a time; the AVX512-BF16 kernel broadcasts one pair of a row to every lane.
//! - the right operand (the activations' column matrix, `depth x cols` f32) is converted at each
//!   product's input into pairs ([`pack_pairs`]): element `(k, j)` at
//!   `((k / 2) · cols_pad + j) · 2 + k % 2`, `cols_pad` a multiple of `COL_STEP`, padding zero.
//!   A tile loads 16 pair rows of 16 columns with the row stride `cols_pad · 4` bytes; a vector
//!   loads one pair row of 16 columns.
//!
//! Numerics: both inputs are rounded to bf16 (8-bit significand, round to nearest even: a
//! relative error up to 2⁻⁹ each), products and sums are f32 (`vdpbf16ps` rounds each pair's
//! sum, the tile unit its own way, so the two units differ by the rounding of f32 sums). Over a
//! depth of `K` the error is about `2⁻⁸ · sqrt(K)` times the typical product, far below what the
//! inputs' rounding already is relative to the sum of absolute products (the tests bound
//! `4 · 2⁻⁹` of it).

#![allow(unsafe_code)]

#[cfg(target_arch = "x86_64")]
mod dot;
mod features;
mod operands;
#[cfg(target_arch = "x86_64")]
mod tiles;

pub(crate) use features::Bf16Unit;
use operands::Operands;
pub(crate) use operands::{COL_STEP, PackedWeights, to_bf16};

/// `dst (+)= lhs · rhs` in bf16 with f32 sums on `unit`: `dst` `lhs.rows x cols` (row stride
/// `dst_stride`), `rhs` `lhs.depth x cols` f32 (row stride `rhs_stride`), converted into pairs
/// (in the calling thread's reusable buffer) first. `dst` is overwritten, or added to when
/// `accumulate`. Runs on the calling thread.
///
/// Panics where `unit` is not [`Bf16Unit::available`] or an operand is shorter than its shape.
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul_bf16(
    unit: Bf16Unit,
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &PackedWeights,
    rhs: &[f32],
    rhs_stride: usize,
    cols: usize,
    accumulate: bool,
) {
    PAIRS.with_borrow_mut(|pairs| product(unit, dst, dst_stride, lhs, rhs, rhs_stride, cols, accumulate, pairs));
}

thread_local! {
    /// Each thread's pairs of the right operand, grown to the largest product it has run.
    static PAIRS: std::cell::RefCell<Vec<u16>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// [`matmul_bf16`] with the pairs' buffer given.
#[allow(clippy::too_many_arguments)]
fn product(
    unit: Bf16Unit,
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &PackedWeights,
    rhs: &[f32],
    rhs_stride: usize,
    cols: usize,
    accumulate: bool,
    pairs: &mut Vec<u16>,
) {
    let (rows, depth) = (lhs.rows, lhs.depth);
    if rows == 0 || cols == 0 {
        return;
    }
    assert!(unit.available(), "the processor lacks {unit:?}");
    assert!(cols <= dst_stride && dst.len() >= (rows - 1) * dst_stride + cols, "dst is shorter than {rows}x{cols}");
    assert!(depth == 0 || (cols <= rhs_stride && rhs.len() >= (depth - 1) * rhs_stride + cols), "rhs is short");
    let cols_pad = cols.next_multiple_of(COL_STEP);
    pack_pairs(pairs, rhs, rhs_stride, [depth, cols], lhs.depth_pad, cols_pad);
    let operands = Operands { lhs, pairs, cols, cols_pad };
    #[cfg(target_arch = "x86_64")]
    match unit {
        Bf16Unit::Tiles => tiles::product(dst, dst_stride, &operands, accumulate),
        Bf16Unit::DotProducts => dot::product(dst, dst_stride, &operands, accumulate),
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (operands, accumulate);
}

/// Writes `rhs` (`depth x cols` f32, row stride `stride`) into `pairs` in the pair layout of the
/// module's doc, `depth_pad / 2` pair rows of `cols_pad` columns, zeros in the padding.
fn pack_pairs(
    pairs: &mut Vec<u16>,
    rhs: &[f32],
    stride: usize,
    [depth, cols]: [usize; 2],
    depth_pad: usize,
    cols_pad: usize,
) {
    pairs.clear();
    pairs.resize(depth_pad * cols_pad, 0);
    #[cfg(target_arch = "x86_64")]
    if features::Bf16Unit::DotProducts.available() {
        return dot::pack_pairs(pairs, rhs, stride, [depth, cols], cols_pad);
    }
    for k in 0..depth {
        let row = &rhs[k * stride..][..cols];
        for (j, &x) in row.iter().enumerate() {
            pairs[((k / 2) * cols_pad + j) * 2 + k % 2] = to_bf16(x);
        }
    }
}

/// The f32 value of the bf16 bit pattern `b`.
#[cfg(test)]
pub(crate) fn from_bf16(b: u16) -> f32 {
    f32::from_bits(u32::from(b) << 16)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random value in `[-1, 1)` for index `i` and seed `s`.
    fn value(i: usize, s: u64) -> f32 {
        let mut z = (i as u64).wrapping_add(s.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }

    #[test]
    fn rounding_to_bf16_is_to_nearest_even() {
        assert_eq!(from_bf16(to_bf16(1.0)), 1.0);
        assert_eq!(from_bf16(to_bf16(-2.5)), -2.5);
        // 1 + 2⁻⁸ lies halfway between 1 and 1 + 2⁻⁷: ties to the even significand, 1.
        assert_eq!(from_bf16(to_bf16(1.0 + 1.0 / 256.0)), 1.0);
        assert_eq!(from_bf16(to_bf16(1.0 + 3.0 / 256.0)), 1.0 + 4.0 / 256.0);
        assert_eq!(from_bf16(to_bf16(1.0 + 1.5 / 256.0)), 1.0 + 2.0 / 256.0);
        assert!(from_bf16(to_bf16(f32::NAN)).is_nan());
        assert_eq!(from_bf16(to_bf16(f32::INFINITY)), f32::INFINITY);
        for i in 0..1000 {
            let x = value(i, 1) * 100.0;
            assert!((from_bf16(to_bf16(x)) - x).abs() <= x.abs() / 256.0, "{x}");
        }
    }

    /// The pair layout, by whichever packer the processor runs, against the definition.
    #[test]
    fn pairs_follow_the_layout() {
        let [depth, cols, stride] = [7, 19, 23];
        let rhs: Vec<f32> = (0..depth * stride).map(|i| value(i, 2)).collect();
        let (depth_pad, cols_pad) = (32, 32);
        let mut pairs = vec![7u16; 3];
        pack_pairs(&mut pairs, &rhs, stride, [depth, cols], depth_pad, cols_pad);
        assert_eq!(pairs.len(), depth_pad * cols_pad);
        for kp in 0..depth_pad / 2 {
            for j in 0..cols_pad {
                for half in 0..2 {
                    let k = 2 * kp + half;
                    let want = if k < depth && j < cols { to_bf16(rhs[k * stride + j]) } else { 0 };
                    assert_eq!(pairs[(kp * cols_pad + j) * 2 + half], want, "k {k} j {j}");
                }
            }
        }
    }

    /// The f32 product of the bf16-rounded operands, and the sum of absolute products: the
    /// reference a bf16 product must meet up to the rounding of its f32 sums.
    fn reference(lhs: &[f32], rhs: &[f32], [rows, cols, depth]: [usize; 3]) -> (Vec<f64>, Vec<f64>) {
        let round = |x: f32| f64::from(from_bf16(to_bf16(x)));
        let mut exact = vec![0.0; rows * cols];
        let mut magnitude = vec![0.0; rows * cols];
        for r in 0..rows {
            for j in 0..cols {
                for k in 0..depth {
                    let p = round(lhs[r * depth + k]) * round(rhs[k * cols + j]);
                    exact[r * cols + j] += p;
                    magnitude[r * cols + j] += p.abs();
                }
            }
        }
        (exact, magnitude)
    }

    /// Every unit the processor has, on shapes with partial row, column and depth blocks, with
    /// and without accumulation, against the f32 product of the rounded inputs (within the
    /// rounding of f32 sums) and the f32 product of the inputs (within bf16's rounding); the tile
    /// unit against the dot-product unit where both exist. Says which units it skipped.
    #[test]
    fn every_unit_meets_the_reference() {
        let units: Vec<_> = Bf16Unit::ALL.into_iter().filter(|u| u.available()).collect();
        for unit in Bf16Unit::ALL.into_iter().filter(|u| !u.available()) {
            eprintln!("skipped: the processor lacks the bf16 unit {unit:?}");
        }
        let shapes = [[1, 1, 1], [5, 7, 3], [12, 32, 64], [13, 33, 65], [40, 130, 577], [64, 128, 1152], [3, 200, 31]];
        for (s, [rows, cols, depth]) in shapes.into_iter().enumerate() {
            let lhs: Vec<f32> = (0..rows * depth).map(|i| value(i, 10 + s as u64)).collect();
            let rhs: Vec<f32> = (0..depth * cols).map(|i| value(i, 20 + s as u64) * 3.0).collect();
            let (exact, magnitude) = reference(&lhs, &rhs, [rows, cols, depth]);
            let packed = PackedWeights::new(&lhs, depth, [rows, depth]);
            let mut results = Vec::new();
            for &unit in &units {
                let dst_stride = cols + 3;
                let mut dst = vec![-5.0f32; rows * dst_stride];
                matmul_bf16(unit, &mut dst, dst_stride, &packed, &rhs, cols, cols, false);
                let mut twice = dst.clone();
                matmul_bf16(unit, &mut twice, dst_stride, &packed, &rhs, cols, cols, true);
                for r in 0..rows {
                    for j in 0..dst_stride {
                        let (got, sum) = (dst[r * dst_stride + j], twice[r * dst_stride + j]);
                        if j >= cols {
                            assert_eq!((got, sum), (-5.0, -5.0), "{unit:?} {rows}x{cols}x{depth}: padding written");
                            continue;
                        }
                        let (want, scale) = (exact[r * cols + j], magnitude[r * cols + j].max(1e-6));
                        let err = (f64::from(got) - want).abs() / scale;
                        assert!(err < 1e-5, "{unit:?} {rows}x{cols}x{depth} ({r}, {j}): {got} vs {want}");
                        let f32_sum: f64 = (0..depth).map(|k| f64::from(lhs[r * depth + k] * rhs[k * cols + j])).sum();
                        assert!((f64::from(got) - f32_sum).abs() / scale < 4.0 / 512.0, "{unit:?}: against f32");
                        assert!((f64::from(sum) - 2.0 * f64::from(got)).abs() / scale < 1e-5, "{unit:?}: accumulated");
                    }
                }
                results.push((unit, dst));
            }
            if let [(a, first), (b, second)] = &results[..] {
                let worst = first.iter().zip(second).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
                let scale = magnitude.iter().copied().fold(0.0, f64::max) as f32;
                assert!(worst <= scale * 1e-5, "{a:?} against {b:?} at {rows}x{cols}x{depth}: {worst}");
            }
        }
    }
}
