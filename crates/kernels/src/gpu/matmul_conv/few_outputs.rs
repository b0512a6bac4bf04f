//! Few output channels: the product before the shift, for GPU inference.
//!
//! The flow head's last convolution (3x3, 256 -> 2 channels, every update iteration) built a
//! `2304 x H·W` column matrix for a product with two rows: on an H200 the gather took 0.25 ms and
//! the product 0.11 ms of a 4.8-ms iteration. Multiplying first,
//! `Z = W' X` with `W'` the `O·kh·kw x C` weight and `X` the input as it lies, gives `O·kh·kw`
//! planes of the input's size; the output sums their `kh·kw` shifted copies, gathered by the same
//! window indices as the columns (`H·W` pointing at an appended zero). The input is read once and
//! nothing of its size is written: the CPU's `host_few_outputs` in burn's operations. The
//! dispatch decides which convolutions take it (`crate::dispatch`'s few-output rule).

use burn::tensor::Tensor;
use burn::tensor::ops::ConvOptions;

use super::columns::{EpilogueBias, WindowShape, finish, window_indices};
use crate::geometry::conv_output_size;

/// `conv2d(x, weight, bias, options)` (stride 1, groups 1) as the product of the weight with
/// the input, then the sum of the product's shifted planes, then `then` on `[N, O, H_out·W_out]`
/// (as `super::conv2d_by_matmul_then`).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]` as `super::epilogue_bias`
///   prepared it; output `[N, O, H_out, W_out]`
pub(super) fn conv2d_product_first(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<EpilogueBias>,
    options: &ConvOptions<2>,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    let device = x.device();
    let [n, c, h, w] = x.dims();
    let [o, _, kh, kw] = weight.dims();
    let [out_h, out_w] = conv_output_size("conv2d_product_first", [h, w], [kh, kw], options);
    let (taps, pixels) = (kh * kw, out_h * out_w);
    // Rows (o, ky, kx) of Z, each a plane of the input's size.
    let weight = weight.permute([0, 2, 3, 1]).reshape([1, o * taps, c]);
    let weight = if n > 1 { weight.expand([n, o * taps, c]) } else { weight };
    let z = weight.matmul(x.reshape([n, c, h * w]));
    let z = Tensor::cat(vec![z, Tensor::zeros([n, o * taps, 1], &device)], 2);
    // Row (o, t) reads tap t's window: the window indices once per output channel.
    let indices =
        window_indices(WindowShape::new([h, w], [kh, kw], options), o, &device).reshape([1, o * taps, pixels]);
    let indices = if n > 1 { indices.expand([n, o * taps, pixels]) } else { indices };
    let out = z.gather(2, indices).reshape([n, o, taps, pixels]).sum_dim(2).reshape([n, o, pixels]);
    finish(out, bias, then, [out_h, out_w])
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::{Device, Distribution};

    use super::*;
    use dgstereo_core::tensor::max_abs_diff;

    /// Against burn's convolution: one to four outputs, a batch of two, padded, unpadded,
    /// asymmetric, dilated and non-square kernels, a single row.
    #[test]
    fn the_product_first_agrees_with_burn() {
        let device = Device::flex();
        let opts = |padding, dilation| ConvOptions::new_with_padding([1, 1], padding, [dilation, dilation], 1);
        let same = [(1, 1), (1, 1)];
        for (n, [c, o], [h, w], [kh, kw], options) in [
            (1, [40, 2], [9, 13], [3, 3], opts(same, 1)), // the flow head
            (2, [32, 1], [6, 5], [3, 3], opts(same, 1)),
            (1, [33, 4], [8, 9], [3, 3], opts([(0, 0), (0, 0)], 1)),
            (1, [32, 3], [8, 9], [3, 3], opts([(2, 1), (0, 3)], 1)),
            (2, [36, 2], [10, 12], [3, 3], opts([(2, 2), (2, 2)], 2)),
            (1, [32, 2], [7, 8], [1, 3], opts([(0, 0), (1, 1)], 1)),
            (1, [32, 2], [1, 11], [3, 3], opts(same, 1)),
        ] {
            let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
            let wt = Tensor::<4>::random([o, c, kh, kw], Distribution::Normal(0.0, 0.3), &device);
            let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
            let reference = conv2d(x.clone(), wt.clone(), Some(b.clone()), options.clone());
            let scale = reference.clone().abs().max().into_scalar::<f32>();
            let bias = super::super::columns::epilogue_bias(Some(b), o, true);
            let got = conv2d_product_first(x, wt, bias, &options, |t| t);
            assert_eq!(got.dims(), reference.dims());
            let err = max_abs_diff(got, reference) / scale;
            assert!(err < 1e-5, "n {n} c {c} o {o} {h}x{w} {kh}x{kw}: {err}");
        }
    }
}
