//! A convolution as one matrix product over shifted copies of the input, for GPU inference.
//!
//! Design decision: burn 0.22's convolution on wgpu/Vulkan tunes between a direct kernel and
//! implicit-GEMM kernels on the tensor cores (`simple_sync_cmma`). On the update loop's shapes (3x3
//! with 256 to 384 input channels) the implicit-GEMM kernels ask for 90 KB of workgroup memory
//! where Vulkan allows 48 KB, so burn falls back to its direct kernel: about 2 TFLOP/s on an H200
//! in f16 and f32 alike, 47 % of a KITTI pass in the GRU at 1/4 resolution (burn's tuning database
//! from a tuning run). burn's matrix product does run on the tensor cores at those sizes
//! (its tuning picked `matmul_simple_cyclic_cmma_multi_rows`). So on devices other than the CPU a
//! convolution is built from burn's operations as an explicit im2col, the input's `kh·kw` shifted
//! windows stacked along the channels (`[N, C·kh·kw, H_out·W_out]`), and one product with the
//! weight as `[O, C·kh·kw]`. It costs the column matrix's memory (`kh·kw` times the input's), which
//! a GPU has, and it differentiates on every backend, but autodiff would keep every column matrix
//! for the backward pass, so training keeps burn's convolution (the dispatch's `suits_product` names the shapes it takes). The CPU
//! never takes it: its host kernels are faster there. burn's convolution stays the reference, and
//! the tests check both agree, gradients included.
//!
//! The column matrix is gathered in one `select` from the input with a zero column appended
//! (`GpuColumns::Gathered`): the shifted windows sliced one by one (`GpuColumns::Windows`) cost a
//! copy kernel each on wgpu (a window that starts off the 64-byte alignment of a binding offset is
//! no view), ten kernels a 3x3 convolution and fifty for the motion encoder's 7x7, every
//! iteration. The gathered rows are ordered `(c, ky, kx)`, the weight's own layout, so the weight
//! needs no reordering either. The indices are built on the host once per shape and kept
//! (`window_indices`).
//!
//! The gathered columns take a stride as well, so the encoders' strided convolutions, which burn
//! ran with its direct kernel (31 ms of a 0.2-s KITTI pass on an H200), take the product too.
//!
//! `stock-route=conv` turns the route off, `im2col` the gathered columns and `strided` the
//! strided convolutions' share ([`crate::settings::GpuRoute`]), so a GPU run can measure what each gains.

mod columns;
mod few_outputs;
mod shared_columns;

pub(crate) use shared_columns::SharedColumns;

use burn::tensor::Tensor;
use burn::tensor::ops::{ConvOptions, PadMode};

#[cfg(test)]
use columns::window_indices;
use columns::{EpilogueBias, WindowShape, epilogue_bias, finish, gathered_columns};

use crate::algorithm::{GpuColumns, GpuConvForm};
use crate::geometry::conv_output_size;

/// An unpadded 1x1 convolution at stride 1: a product with the input as it lies.
fn is_pointwise(options: &ConvOptions<2>, kernel: [usize; 2]) -> bool {
    kernel == [1, 1] && options.stride == [1, 1] && options.padding == [(0, 0), (0, 0)]
}

/// `conv2d(x, weight, bias, options)` for groups 1 as one matrix product over the input's
/// shifted windows (explicit im2col from burn's operations) in the `form` the dispatch chose:
/// the columns gathered or from the windows, or the product first and the shift after
/// (`few_outputs`).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`
/// - output `[N, O, H_out, W_out]`, `H_out = (H + top + bottom - dil·(kh - 1) - 1) / stride + 1`
///   (likewise `W_out`)
///
/// # Panics
/// Where `options` has groups, a stride other than 1 with the windows, the channels do not
/// match, or the padded input is smaller than the (dilated) kernel.
pub(crate) fn conv2d_by_matmul(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
    form: GpuConvForm,
) -> Tensor<4> {
    // Nothing follows the product, so there is no epilogue to fuse the bias into.
    conv2d_by_matmul_then(x, weight, bias, options, GpuConvForm { fused_epilogue: false, ..form }, |out| out)
}

/// [`conv2d_by_matmul`] followed by `then`, element-wise work on the output as the product
/// leaves it, `[N, O, H_out·W_out]`. The bias and `then` are issued on the product's own shape,
/// every operand prepared before the product, so burn's fusion takes them into the product's
/// epilogue (run inside the product's kernel or as one fused kernel after it, as its autotune
/// picks): it takes element-wise operations of the product's shape and stops at the first
/// operation of another shape (the bias reshaped after the product is one, which leaves
/// every bias add and activation of the update loop in kernels of their own). Where the form
/// has no fused epilogue (``stock-route=epilogue``) the bias is added after the product, for
/// comparison (see [`epilogue_bias`]).
///
/// # Shapes
/// - as [`conv2d_by_matmul`]; `then` maps `[N, O, H_out·W_out]` to the same shape
pub(crate) fn conv2d_by_matmul_then(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
    form: GpuConvForm,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    let bias = epilogue_bias(bias, weight.dims()[0], form.fused_epilogue);
    if form.product_first {
        return few_outputs::conv2d_product_first(x, weight, bias, options, then);
    }
    conv2d_by_matmul_with(x, weight, bias, options, form.columns, then)
}

/// [`conv2d_by_matmul_then`] with the column matrix built as `columns` says (an unpadded 1x1 at
/// stride 1 takes the input as it lies either way).
fn conv2d_by_matmul_with(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<EpilogueBias>,
    options: &ConvOptions<2>,
    columns: GpuColumns,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    assert!(options.groups == 1, "conv2d_by_matmul: groups 1 only");
    let [n, c, h, w] = x.dims();
    let [o, cw, kh, kw] = weight.dims();
    assert_eq!(c, cw, "conv2d_by_matmul: input has {c} channels, the weight expects {cw}");
    let out_size = conv_output_size("conv2d_by_matmul", [h, w], [kh, kw], options);
    let [out_h, out_w] = out_size;
    let k = kh * kw * c;
    let (columns, weight) = match columns {
        _ if is_pointwise(options, [kh, kw]) => (x.reshape([n, c, h * w]), weight.reshape([1, o, k])),
        GpuColumns::Gathered => {
            (gathered_columns(x, WindowShape::new([h, w], [kh, kw], options)), weight.reshape([1, o, k]))
        }
        GpuColumns::Windows => {
            assert!(options.stride == [1, 1], "conv2d_by_matmul: the windows take stride 1 only");
            let [(top, bottom), (left, right)] = options.padding;
            let [dh, dw] = options.dilation;
            let padded = if top + bottom + left + right > 0 {
                x.pad([(top, bottom), (left, right)], PadMode::Constant(0.0))
            } else {
                x
            };
            // Windows in (ky, kx) order, each [N, C, H_out, W_out]: rows (ky, kx, c) of the columns.
            let windows: Vec<Tensor<4>> = (0..kh * kw)
                .map(|tap| {
                    let (y, x) = (dh * (tap / kw), dw * (tap % kw));
                    padded.clone().slice([0..n, 0..c, y..y + out_h, x..x + out_w])
                })
                .collect();
            (Tensor::cat(windows, 1).reshape([n, k, out_h * out_w]), weight.permute([0, 2, 3, 1]).reshape([1, o, k]))
        }
    };
    let weight = if n > 1 { weight.expand([n, o, k]) } else { weight };
    finish(weight.matmul(columns), bias, then, out_size)
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::{Device, Distribution};

    use super::*;
    use dgstereo_core::tensor::max_abs_diff;

    fn options(padding: [(usize, usize); 2], dilation: usize) -> ConvOptions<2> {
        ConvOptions::new_with_padding([1, 1], padding, [dilation, dilation], 1)
    }

    fn strided(stride: [usize; 2], padding: [(usize, usize); 2]) -> ConvOptions<2> {
        ConvOptions::new_with_padding(stride, padding, [1, 1], 1)
    }

    /// Largest difference from burn's convolution relative to its output's largest magnitude.
    fn relative_error(
        n: usize,
        [c, o]: [usize; 2],
        [h, w]: [usize; 2],
        k: [usize; 2],
        opts: ConvOptions<2>,
        columns: GpuColumns,
    ) -> f32 {
        let device = Device::flex();
        let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let wt = Tensor::<4>::random([o, c, k[0], k[1]], Distribution::Normal(0.0, 0.3), &device);
        let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
        let reference = conv2d(x.clone(), wt.clone(), Some(b.clone()), opts.clone());
        let got = conv2d_by_matmul_with(x, wt, epilogue_bias(Some(b), o, true), &opts, columns, |t| t);
        assert_eq!(got.dims(), reference.dims());
        let scale = reference.clone().abs().max().into_scalar::<f32>().max(1e-6);
        max_abs_diff(got, reference) / scale
    }

    #[test]
    fn the_matmul_convolution_agrees_with_burn() {
        let same = [(1, 1), (1, 1)];
        for columns in [GpuColumns::Gathered, GpuColumns::Windows] {
            for (n, co, hw, k, opts) in [
                (1, [16, 24], [9, 13], [3, 3], options(same, 1)),
                (2, [5, 7], [6, 5], [3, 3], options(same, 1)),
                (1, [2, 8], [11, 10], [7, 7], options([(3, 3), (3, 3)], 1)), // the motion encoder's flow conv
                (1, [3, 4], [8, 9], [3, 3], options([(0, 0), (0, 0)], 1)),   // no padding
                (1, [3, 4], [8, 9], [3, 3], options([(2, 1), (0, 3)], 1)),   // asymmetric
                (2, [4, 3], [10, 12], [3, 3], options([(2, 2), (2, 2)], 2)), // dilated
                (1, [6, 2], [7, 8], [1, 3], options([(0, 0), (1, 1)], 1)),   // not square
                (1, [3, 5], [2, 3], [3, 3], options([(4, 4), (3, 3)], 1)),   // padding wider than the input
                (2, [6, 5], [4, 7], [1, 1], options([(0, 0), (0, 0)], 1)),   // 1x1: the input as it lies
            ] {
                let err = relative_error(n, co, hw, k, opts, columns);
                assert!(err < 1e-5, "{columns:?} n {n} {co:?} {hw:?} {k:?}: {err}");
            }
        }
    }

    /// Strided convolutions (the encoders' stems and downsampling layers) take the gathered
    /// columns only: even and odd sizes, 1x1, 3x3 and 7x7 kernels, a stride per axis, dilation.
    #[test]
    fn the_gathered_columns_take_a_stride() {
        let same = [(1, 1), (1, 1)];
        for (n, co, hw, k, opts) in [
            (1, [3, 8], [12, 15], [7, 7], strided([2, 2], [(3, 3), (3, 3)])), // the stem
            (2, [6, 5], [9, 10], [3, 3], strided([2, 2], same)),              // a layer's first block
            (1, [6, 5], [9, 10], [1, 1], strided([2, 2], [(0, 0), (0, 0)])),  // its projection
            (1, [4, 3], [8, 11], [3, 3], strided([1, 3], [(2, 0), (1, 2)])),  // a stride per axis
            (1, [4, 3], [13, 11], [3, 3], ConvOptions::new_with_padding([2, 2], same, [2, 2], 1)),
        ] {
            let err = relative_error(n, co, hw, k, opts, GpuColumns::Gathered);
            assert!(err < 1e-5, "n {n} {co:?} {hw:?} {k:?}: {err}");
        }
    }

    /// The gathered indices of a small case, written out: a 2x3 input, a 3x3 kernel, padding 1;
    /// 6 is the appended zero.
    #[test]
    fn gathered_indices_read_the_window_or_the_zero() {
        let shape = WindowShape::new([2, 3], [3, 3], &options([(1, 1), (1, 1)], 1));
        let indices = shape.indices();
        assert_eq!(indices.len(), 9 * 6);
        assert_eq!(&indices[..6], &[6, 6, 6, 6, 0, 1]); // tap (0, 0): up and left
        assert_eq!(&indices[4 * 6..5 * 6], &[0, 1, 2, 3, 4, 5]); // the centre tap reads the input
        assert_eq!(&indices[8 * 6..], &[4, 5, 6, 6, 6, 6]); // tap (2, 2): down and right
    }

    /// The route is exactly burn's convolution in value, so its gradients (through pad, slice,
    /// cat, select, reshape and matmul) must be burn's convolution's too.
    #[test]
    fn the_matmul_convolution_has_the_gradients_of_burns() {
        let device = Device::flex().autodiff();
        let opts = options([(1, 1), (1, 1)], 1);
        for columns in [GpuColumns::Gathered, GpuColumns::Windows] {
            let x = Tensor::<4>::random([2, 4, 6, 7], Distribution::Normal(0.0, 1.0), &device).require_grad();
            let wt = Tensor::<4>::random([5, 4, 3, 3], Distribution::Normal(0.0, 0.3), &device).require_grad();
            let b = Tensor::<1>::random([5], Distribution::Normal(0.0, 1.0), &device).require_grad();
            let target = Tensor::<4>::random([2, 5, 6, 7], Distribution::Normal(0.0, 1.0), &device);
            let loss = |out: Tensor<4>| (out * target.clone()).sum();
            let g1 = loss(conv2d(x.clone(), wt.clone(), Some(b.clone()), opts.clone())).backward();
            let g2 = loss(conv2d_by_matmul_with(
                x.clone(),
                wt.clone(),
                epilogue_bias(Some(b.clone()), 5, true),
                &opts,
                columns,
                |t| t,
            ))
            .backward();
            for (name, a, b) in [
                ("input", x.grad(&g1).unwrap(), x.grad(&g2).unwrap()),
                ("weight", wt.grad(&g1).unwrap(), wt.grad(&g2).unwrap()),
            ] {
                let scale = a.clone().abs().max().into_scalar::<f32>();
                let err = max_abs_diff(a, b) / scale;
                assert!(err < 1e-5, "{columns:?} {name} gradient: {err}");
            }
            let (gb1, gb2) = (b.grad(&g1).unwrap(), b.grad(&g2).unwrap());
            assert!(
                max_abs_diff(gb1.clone().unsqueeze::<4>(), gb2.unsqueeze())
                    <= 1e-4 * gb1.abs().max().into_scalar::<f32>()
            );
        }
    }

    /// The epilogue sees the biased product as `[N, O, H·W]`, with the bias reshaped before the
    /// product or added after it (no epilogue, or the route off), on every way of building the
    /// product: the gathered columns, the windows, a 1x1 on the input as it lies and the
    /// few-outputs product.
    #[test]
    fn the_epilogue_follows_the_biased_product() {
        let device = Device::flex();
        let same = options([(1, 1), (1, 1)], 1);
        for (n, [c, o], [kh, kw], opts, columns) in [
            (1, [8, 6], [3, 3], same.clone(), GpuColumns::Gathered),
            (2, [8, 6], [3, 3], same.clone(), GpuColumns::Windows),
            (2, [8, 6], [1, 1], options([(0, 0), (0, 0)], 1), GpuColumns::Gathered),
            (1, [40, 2], [3, 3], same, GpuColumns::Gathered), // few outputs
        ] {
            let [h, w] = [5, 7];
            let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
            let wt = Tensor::<4>::random([o, c, kh, kw], Distribution::Normal(0.0, 0.3), &device);
            let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
            let extra = Tensor::<4>::random([n, o, h, w], Distribution::Normal(0.0, 1.0), &device);
            let expected = burn::tensor::activation::sigmoid(
                conv2d(x.clone(), wt.clone(), Some(b.clone()), opts.clone()) + extra.clone(),
            );
            let flat = extra.reshape([n, o, h * w]);
            let then = |t: Tensor<3>| burn::tensor::activation::sigmoid(t + flat.clone());
            for fused in [true, false] {
                let bias = epilogue_bias(Some(b.clone()), o, fused);
                let got = if o <= 4 {
                    few_outputs::conv2d_product_first(x.clone(), wt.clone(), bias, &opts, then)
                } else {
                    conv2d_by_matmul_with(x.clone(), wt.clone(), bias, &opts, columns, then)
                };
                assert!(max_abs_diff(got, expected.clone()) < 1e-5, "{columns:?} {kh}x{kw} o {o} fused {fused}");
            }
        }
    }

    /// Index tensors are kept per shape: asking twice gives the same values, and a new shape
    /// gets its own.
    #[test]
    fn index_tensors_are_kept_per_shape() {
        let device = Device::flex();
        let a = WindowShape::new([4, 5], [3, 3], &options([(1, 1), (1, 1)], 1));
        let b = WindowShape { input: [4, 6], ..a };
        let first = window_indices(a, 1, &device).into_data();
        assert_eq!(first, window_indices(a, 1, &device).into_data());
        assert_eq!(window_indices(b, 1, &device).dims(), [9 * 4 * 6]);
        assert_eq!(first.shape().to_vec(), [9 * 4 * 5]);
    }
}
