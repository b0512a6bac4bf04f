//! The host convolution: im2col tiles straight from NCHW and the `gemm` crate, every step
//! parallel; Winograd for the 3x3 stride-1 layers it suits, a shifted-sum kernel for few outputs.
//!
//! Design decision: burn Flex's convolution is the same im2col + `gemm` product, but before the
//! parallel tiles it transposes the whole input to NHWC and flattens the weights on the calling
//! thread, with the channel as the innermost loop over an NCHW source, which left one core idle
//! for a large share of a forward pass. Here the weight `[O, C, kh, kw]` is already the
//! row-major `O x (C·kh·kw)` matrix the product needs, each tile of output rows builds its own
//! column matrix from NCHW rows (a shifted copy per `(c, ky, kx)`), and the product writes into
//! the NCHW output directly. 3x3 stride-1 convolutions with enough channels and pixels take
//! Winograd F(4x4, 3x3) or F(2x2, 3x3) instead ([`super::winograd`]). burn's convolution stays
//! the reference, and the tests check both agree.

use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_core::tensor::{host_values, reuse_buffer, zeros_parallel};
use rayon::prelude::*;

use super::columns::image_columns;
use super::few_outputs::few_outputs_conv;
use super::winograd::{Conv3x3, Pending, split_first, split_second, variant, winograd_bf16_conv, winograd_conv};
use crate::algorithm::{Bf16Unit, ConvAlgorithm, WinogradTile};
use crate::bf16_product::{PackedWeights, matmul_bf16};
use crate::geometry::{Epilogue, band_jobs, conv_output_size};
use crate::product::matmul_into;

/// Output pixels per tile (whole output rows, at least one): enough columns for an efficient
/// product, few enough for many tiles and small column buffers (the smallest that ran as fast
/// as larger ones, so the least memory).
const TILE_PIXELS: usize = 128;

/// Column-matrix elements per tile: shallow columns (few input channels times kernel taps) get
/// more than [`TILE_PIXELS`] pixels, up to the matrix a 3x3 layer of 64 channels has at 128
/// pixels, so their products are fewer and larger; deep columns keep [`TILE_PIXELS`].
const COLUMN_BUDGET: usize = 128 * 576;

/// `conv2d(x, weight, bias)` with `options` (groups = 1) computed on the host by `algorithm`
/// (the dispatch's choice), `epilogue` applied as the output is written.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`
/// - output: `[N, O, H_out, W_out]` with `H_out = (H + 2·pad - dil·(kh - 1) - 1) / stride + 1`
pub(crate) fn conv2d_host(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
    algorithm: ConvAlgorithm,
    epilogue: Epilogue,
) -> Tensor<4> {
    let device: Device = x.device();
    let (x_dims, w_dims) = (x.dims(), weight.dims());
    let (x, wt) = (host_values(x), host_values(weight));
    let bias = bias.map(host_values);
    let (out, dims) = conv2d_host_slices(&x, x_dims, &wt, w_dims, bias.as_deref(), options, algorithm, epilogue);
    Tensor::from_data(TensorData::new(out, dims), &device)
}

/// [`conv2d_host`] on host buffers (row-major NCHW input, OIHW weight), for kernels that chain
/// several steps without going through tensors. Returns the output and its dimensions.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `weight`: `w_dims = [O, C, kh, kw]`; `bias`: `[O]`
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv2d_host_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
    algorithm: ConvAlgorithm,
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    match algorithm {
        ConvAlgorithm::Winograd { tile, blocks } => {
            check_shapes(x, x_dims, wt, w_dims, options);
            let conv = Conv3x3 { x, x_dims, wt, o: w_dims[0], bias, padding: options.padding, epilogue };
            winograd_conv(tile, blocks, &conv)
        }
        ConvAlgorithm::FewOutputs => {
            check_shapes(x, x_dims, wt, w_dims, options);
            few_outputs_conv(x, x_dims, wt, w_dims, bias, options.padding, options.dilation, epilogue)
        }
        ConvAlgorithm::WinogradBf16 { tile, unit } => {
            check_shapes(x, x_dims, wt, w_dims, options);
            let conv = Conv3x3 { x, x_dims, wt, o: w_dims[0], bias, padding: options.padding, epilogue };
            winograd_bf16_conv(tile, unit, &conv)
        }
        ConvAlgorithm::Im2col => im2col_conv_slices(x, x_dims, wt, w_dims, bias, options, epilogue, None),
        ConvAlgorithm::Im2colBf16(unit) => {
            im2col_conv_slices(x, x_dims, wt, w_dims, bias, options, epilogue, Some(unit))
        }
    }
}

/// The second of two host convolutions that share input channels, waiting for the rest of its
/// input ([`conv2d_host_shared_first`]).
pub(crate) struct PendingConv(Pending);

/// Two 3x3 convolutions by Winograd with `tile` whose inputs share channels, the shared ones
/// transformed once (the ConvGRU's gates over `[h, x]` and candidate over `[r·h, x]`, module
/// `winograd`'s `split`): returns the first convolution's output (weight `wt_first` over all of
/// `x`, bias `bias_first`) and the second's products over the shared channels, the last `shared`
/// of `x` and of the second's input, whose weight `wt_second` has `c2` input channels.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `wt_first`: `[O1, C, 3, 3]`; `wt_second`: `[O2, c2, 3, 3]`
/// - output (returned without its dimensions) `[N, O1, H_out, W_out]`
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv2d_host_shared_first(
    x: &[f32],
    x_dims: [usize; 4],
    [wt_first, wt_second]: [&[f32]; 2],
    [o1, o2]: [usize; 2],
    c2: usize,
    shared: usize,
    bias_first: Option<&[f32]>,
    options: &ConvOptions<2>,
    tile: WinogradTile,
    unit: Option<Bf16Unit>,
) -> (Vec<f32>, PendingConv) {
    let c = x_dims[1];
    check_shapes(x, x_dims, wt_first, [o1, c, 3, 3], options);
    let (out, pending) = split_first(
        variant(tile),
        x,
        x_dims,
        [wt_first, wt_second],
        [o1, o2],
        c2,
        shared,
        bias_first,
        options.padding,
        Epilogue::Linear,
        unit,
    );
    (out.0, PendingConv(pending))
}

/// The second convolution of [`conv2d_host_shared_first`]: its own input channels `x` (the first
/// `c2 - shared`), with its bias.
///
/// # Shapes
/// - `x`: `x_dims = [N, c2 - shared, H, W]`; output `[N, O2, H_out, W_out]`
pub(crate) fn conv2d_host_shared_second(
    pending: PendingConv,
    x: &[f32],
    x_dims: [usize; 4],
    bias: Option<&[f32]>,
) -> (Vec<f32>, [usize; 4]) {
    split_second(pending.0, x, x_dims, bias, Epilogue::Linear)
}

/// The asserts every path makes: groups = 1, matching channels and buffer lengths, an input
/// (with its padding) at least as large as the dilated kernel. Returns the output's `[H_out, W_out]`.
fn check_shapes(x: &[f32], x_dims: [usize; 4], wt: &[f32], w_dims: [usize; 4], options: &ConvOptions<2>) -> [usize; 2] {
    let [n, c, h, w] = x_dims;
    let [o, cw, kh, kw] = w_dims;
    assert_eq!(options.groups, 1, "conv2d_host: grouped convolutions are not supported");
    assert_eq!(c, cw, "conv2d_host: input has {c} channels, the weight expects {cw}");
    assert_eq!(x.len(), n * c * h * w, "conv2d_host: input buffer does not match {x_dims:?}");
    assert_eq!(wt.len(), o * c * kh * kw, "conv2d_host: weight buffer does not match {w_dims:?}");
    conv_output_size("conv2d_host", [h, w], [kh, kw], options)
}

/// [`conv2d_host_slices`] by im2col tiles and `gemm`, for any shape; the products in bf16 with
/// f32 sums on `unit` where it is given (the weight converted once per call).
#[allow(clippy::too_many_arguments)]
pub(crate) fn im2col_conv_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
    epilogue: Epilogue,
    unit: Option<Bf16Unit>,
) -> (Vec<f32>, [usize; 4]) {
    let [out_h, out_w] = check_shapes(x, x_dims, wt, w_dims, options);
    let [n, c, h, w] = x_dims;
    let [o, _, kh, kw] = w_dims;
    let k = c * kh * kw;
    let plane = out_h * out_w;
    let tile_pixels = (COLUMN_BUDGET / k.max(1)).max(TILE_PIXELS);
    let rows_per_tile = (tile_pixels / out_w.max(1)).clamp(1, out_h.max(1));
    let tiles_per_image = out_h.div_ceil(rows_per_tile);
    let packed = unit.map(|unit| (unit, PackedWeights::new(wt, k, [o, k])));

    // One job per (image, tile of output rows) with its rows of every output plane; its O x P
    // product goes to the thread's block buffer, then into those rows with the bias and the
    // epilogue (no per-tile allocation, no second pass over the whole output).
    let mut out = zeros_parallel(n * o * plane);
    let jobs = band_jobs(&mut out, o, plane, rows_per_tile * out_w);
    jobs.into_par_iter().enumerate().for_each(|(t, planes)| {
        let (b, tile) = (t / tiles_per_image, t % tiles_per_image);
        let oy0 = tile * rows_per_tile;
        let oy1 = (oy0 + rows_per_tile).min(out_h);
        let p = (oy1 - oy0) * out_w;
        // Column matrix, K x P row-major: row (ci, ky, kx), column (oy, ox) of the tile. The
        // buffers are the thread's, reused across calls; every element of both is written below
        // (zeros where the kernel reaches into the padding), so they are never cleared first.
        COLUMNS.with_borrow_mut(|[col, block]| {
            let (col, block) = (reuse_buffer(col, k * p), reuse_buffer(block, o * p));
            image_columns(col, &x[b * c * h * w..(b + 1) * c * h * w], [c, h, w], [kh, kw], options, out_w, oy0..oy1);
            match &packed {
                Some((unit, packed)) => matmul_bf16(*unit, block, p, packed, col, p, p, false),
                None => matmul_into(block, wt, k, col, [o, p, k]),
            }
            for (oc, dst) in planes.into_iter().enumerate() {
                let (src, add) = (&block[oc * p..][..p], bias.map_or(0.0, |v| v[oc]));
                match epilogue {
                    Epilogue::Linear => dst.iter_mut().zip(src).for_each(|(d, s)| *d = s + add),
                    Epilogue::Relu => dst.iter_mut().zip(src).for_each(|(d, s)| *d = (s + add).max(0.0)),
                }
            }
        })
    });
    (out, [n, o, out_h, out_w])
}

thread_local! {
    /// Each worker thread's column matrix and product block, grown to the largest tile it has
    /// built.
    static COLUMNS: std::cell::RefCell<[Vec<f32>; 2]> = const { std::cell::RefCell::new([Vec::new(), Vec::new()]) };
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use burn::tensor::module::conv2d;

    use super::*;
    use crate::dispatch::{host_algorithm, winograd_tile};
    use crate::settings::settings;
    use dgstereo_core::tensor::max_abs_diff;

    /// [`conv2d_host`] by the algorithm the dispatch chooses for the shape.
    fn dispatched(x: Tensor<4>, wt: Tensor<4>, b: Option<Tensor<1>>, options: &ConvOptions<2>) -> Tensor<4> {
        let algorithm = host_algorithm(x.dims(), wt.dims(), options, true, settings());
        conv2d_host(x, wt, b, options, algorithm, Epilogue::Linear)
    }

    #[allow(clippy::too_many_arguments)]
    fn case(n: usize, c: usize, o: usize, hw: [usize; 2], k: [usize; 2], stride: usize, pad: [usize; 2], dil: usize) {
        let device = Device::flex();
        let x = Tensor::<4>::random([n, c, hw[0], hw[1]], Distribution::Normal(0.0, 1.0), &device);
        let wt = Tensor::<4>::random([o, c, k[0], k[1]], Distribution::Normal(0.0, 0.2), &device);
        let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
        let options = ConvOptions::new([stride, stride], pad, [dil, dil], 1);
        let stock = conv2d(x.clone(), wt.clone(), Some(b.clone()), options.clone());
        let host = dispatched(x.clone(), wt.clone(), Some(b.clone()), &options);
        assert_eq!(stock.dims(), host.dims());
        // Relative to the output's largest magnitude: Winograd F(4x4) (taken from 128 tiles)
        // errs by up to ~1e-5 of it, which in absolute terms depends on the random draw.
        let scale = stock.clone().abs().max().into_scalar::<f32>().max(1.0);
        let diff = max_abs_diff(stock.clone(), host) / scale;
        assert!(diff < 4e-5, "n {n} c {c} o {o} {hw:?} k {k:?} s {stride} p {pad:?} d {dil}: {diff}");
        // Without a bias: the stock result minus the bias it added.
        let unbiased = dispatched(x, wt, None, &options);
        let diff = max_abs_diff(stock - b.reshape([1, o as i32, 1, 1]), unbiased) / scale;
        assert!(diff < 4e-5, "no bias: n {n} c {c} o {o} {hw:?} k {k:?}: {diff}");
    }

    #[test]
    fn host_convolution_agrees_with_burn() {
        case(1, 3, 8, [9, 13], [3, 3], 1, [1, 1], 1);
        case(2, 5, 7, [17, 11], [3, 3], 2, [1, 1], 1);
        case(1, 4, 6, [20, 31], [7, 7], 2, [3, 3], 1);
        case(1, 6, 4, [12, 40], [1, 1], 1, [0, 0], 1);
        case(1, 3, 5, [15, 15], [3, 3], 1, [2, 2], 2);
        case(1, 2, 3, [9, 10], [1, 7], 1, [0, 3], 1);
        case(1, 2, 3, [10, 9], [7, 1], 1, [3, 0], 1);
        case(1, 16, 32, [40, 600], [3, 3], 1, [1, 1], 1); // several tiles per image
        // Smaller again: the threads' reused column buffers hold stale values from the case above.
        case(2, 3, 4, [7, 9], [3, 3], 1, [1, 1], 1);
        case(1, 5, 4, [11, 9], [5, 5], 3, [2, 2], 1);
        // Stride 2: odd and even widths, no padding, dilation, a 1x1 projection, a 2-wide input.
        case(1, 3, 5, [9, 12], [3, 3], 2, [0, 0], 1);
        case(2, 4, 3, [13, 15], [3, 3], 2, [2, 2], 2);
        case(1, 6, 5, [10, 11], [1, 1], 2, [0, 0], 1);
        case(1, 2, 3, [6, 2], [3, 3], 2, [1, 1], 1);
        case(1, 8, 16, [40, 300], [3, 3], 2, [1, 1], 1); // several tiles per image, the last partial
        // Deep columns (40 x 9 = 360 rows), one output channel, a 1x1 image.
        case(2, 40, 13, [21, 27], [3, 3], 1, [1, 1], 1);
        case(1, 30, 1, [5, 70], [3, 3], 1, [1, 1], 1);
        case(1, 64, 6, [1, 1], [1, 1], 1, [0, 0], 1);
        // Shapes the dispatch sends to Winograd: F(2x2) (odd width: a partial tile column), F(4x4).
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        assert_eq!(winograd_tile([2, 48, 20, 17], [40, 48, 3, 3], &options), Some(WinogradTile::F2));
        let unpadded = ConvOptions::new([1, 1], [0, 0], [1, 1], 1);
        assert_eq!(winograd_tile([1, 32, 46, 49], [64, 32, 3, 3], &unpadded), Some(WinogradTile::F4));
        case(2, 48, 40, [20, 17], [3, 3], 1, [1, 1], 1);
        case(1, 32, 64, [46, 49], [3, 3], 1, [0, 0], 1);
    }
}
