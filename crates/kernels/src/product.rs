//! The one entry to the `gemm` crate's matrix product, which every host kernel's products take.
//!
//! Design decision: the `gemm` crate's entry point is an `unsafe fn` on raw pointers and
//! strides. It is called here only, in `product`, which asserts that every element its strides
//! reach lies inside the slices it is given; the kernels work on slices.
#![allow(unsafe_code)]

/// `dst = lhs · rhs` on the calling thread by the `gemm` crate: `dst` is `rows x cols` (row
/// stride `cols`), `lhs` `rows x depth` (row stride `lhs_stride`), `rhs` `depth x cols`.
pub fn matmul_into(dst: &mut [f32], lhs: &[f32], lhs_stride: usize, rhs: &[f32], [rows, cols, depth]: [usize; 3]) {
    matmul_strided(dst, cols, lhs, lhs_stride, rhs, cols, [rows, cols, depth]);
}

/// [`matmul_into`] with row strides for all three: `dst` `rows x cols` (row stride
/// `dst_stride`), `lhs` `rows x depth` (`lhs_stride`), `rhs` `depth x cols` (`rhs_stride`).
pub fn matmul_strided(
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &[f32],
    lhs_stride: usize,
    rhs: &[f32],
    rhs_stride: usize,
    dims: [usize; 3],
) {
    matmul_strided_with(dst, dst_stride, lhs, lhs_stride, rhs, rhs_stride, dims, false);
}

/// [`matmul_strided`], or `dst += lhs · rhs` (adding to what `dst` holds) when `accumulate`.
#[allow(clippy::too_many_arguments)]
pub fn matmul_strided_with(
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &[f32],
    lhs_stride: usize,
    rhs: &[f32],
    rhs_stride: usize,
    dims: [usize; 3],
    accumulate: bool,
) {
    product(dst, dst_stride, lhs, lhs_stride, rhs, [rhs_stride, 1], dims, accumulate);
}

/// `dst += lhs · rhs_tᵀ`: `dst` `rows x cols` (row stride `dst_stride`), `lhs` `rows x depth`
/// (`lhs_stride`), `rhs_t` `cols x depth` (row stride `rhs_t_stride`), the product's right
/// operand stored transposed (a convolution's column matrix, for its weight gradient).
#[allow(clippy::too_many_arguments)]
pub fn matmul_transposed_accumulate(
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &[f32],
    lhs_stride: usize,
    rhs_t: &[f32],
    rhs_t_stride: usize,
    dims: [usize; 3],
) {
    product(dst, dst_stride, lhs, lhs_stride, rhs_t, [1, rhs_t_stride], dims, true);
}

/// The one call of the `gemm` crate: `dst (+)= lhs · rhs` with unit column strides for `dst`
/// and `lhs`, and `rhs`'s element `(d, j)` at `d·rhs_strides[0] + j·rhs_strides[1]`.
#[allow(clippy::too_many_arguments)]
fn product(
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &[f32],
    lhs_stride: usize,
    rhs: &[f32],
    [rhs_rs, rhs_cs]: [usize; 2],
    [rows, cols, depth]: [usize; 3],
    accumulate: bool,
) {
    if rows == 0 || cols == 0 {
        return;
    }
    // The furthest element of a `count x width` operand with these strides, plus one.
    let reach = |count: usize, width: usize, [rs, cs]: [usize; 2]| {
        if count == 0 || width == 0 { 0 } else { (count - 1) * rs + (width - 1) * cs + 1 }
    };
    assert!(cols <= dst_stride && depth <= lhs_stride);
    assert!(dst.len() >= reach(rows, cols, [dst_stride, 1]) && lhs.len() >= reach(rows, depth, [lhs_stride, 1]));
    assert!(rhs.len() >= reach(depth, cols, [rhs_rs, rhs_cs]));
    // SAFETY: the asserts keep every element the strides reach inside the three slices, which
    // live through the call; `dst` is read (when `accumulate`) and written only there.
    #[rustfmt::skip]
    unsafe {
        gemm::gemm(rows, cols, depth, dst.as_mut_ptr(), 1, dst_stride as isize, accumulate,
                   lhs.as_ptr(), 1, lhs_stride as isize, rhs.as_ptr(), rhs_cs as isize, rhs_rs as isize,
                   if accumulate { 1.0f32 } else { 0.0 }, 1.0f32, false, false, false, gemm::Parallelism::None);
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The strided product against a plain triple loop, with padding between rows of every
    /// operand (the layout the Winograd path uses); the padding of `dst` stays untouched.
    #[test]
    fn strided_matmul_matches_a_plain_loop() {
        let [rows, cols, depth] = [5, 7, 3];
        let [dst_stride, lhs_stride, rhs_stride] = [11, 4, 9];
        let lhs: Vec<f32> = (0..rows * lhs_stride).map(|i| (i % 13) as f32 - 6.0).collect();
        let rhs: Vec<f32> = (0..depth * rhs_stride).map(|i| (i % 7) as f32 * 0.5 - 1.0).collect();
        let mut dst = vec![-99.0f32; (rows - 1) * dst_stride + cols];
        matmul_strided(&mut dst, dst_stride, &lhs, lhs_stride, &rhs, rhs_stride, [rows, cols, depth]);
        for (i, &got) in dst.iter().enumerate() {
            let (r, c) = (i / dst_stride, i % dst_stride);
            if c >= cols {
                assert_eq!(got, -99.0, "padding at {i} was written");
                continue;
            }
            let expected: f32 = (0..depth).map(|k| lhs[r * lhs_stride + k] * rhs[k * rhs_stride + c]).sum();
            assert_eq!(got, expected, "row {r} column {c}");
        }
    }
}
