//! A 2-D convolution for CPU inference: im2col tiles straight from NCHW and the `gemm` crate,
//! every step parallel.
//!
//! Design decision: burn Flex's convolution is the same im2col + `gemm` product, but before the
//! parallel tiles it transposes the whole input to NHWC and flattens the weights on the calling
//! thread, with the channel as the innermost loop over an NCHW source (one cache line per
//! element). Profiled on this project's 2-core machine, that serial part left one core idle for
//! a large share of a forward pass. Here the weight `[O, C, kh, kw]` is already the row-major
//! `O x (C·kh·kw)` matrix the product needs, each tile of output rows builds its own column
//! matrix from NCHW rows (a shifted copy per `(c, ky, kx)`), and the product writes into the
//! NCHW output directly. Only for plain CPU tensors without autodiff
//! ([`crate::device::host_kernels_apply`]); burn's convolution stays the reference, and the tests
//! check both agree.
//!
//! 3x3 stride-1 convolutions with enough channels and pixels take Winograd F(4x4, 3x3) or
//! F(2x2, 3x3) instead (module `host_winograd`; 1.3x to 2.6x faster than im2col in the
//! `convolution` benchmarks).
//!
//! The `gemm` crate's entry point is an `unsafe fn` taking raw pointers and strides; it is called
//! in one place, `matmul_strided_with`, which every path's products go through and which
//! asserts that every element its strides reach lies inside the slices it is given (the
//! workspace's other `unsafe` blocks are the allocator setting, the SIGPIPE restore and the
//! blocked Winograd path's AVX-512 intrinsics, whose loads and stores go through slices whose
//! length is checked first: `host_winograd::simd`).
#![allow(unsafe_code)]

use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;

use crate::device::host_kernels_apply;
use crate::host_few_outputs::{self, few_outputs_conv};
/// Keeps the Winograd convolutions' transformed weights for reuse while alive (an update loop).
pub use crate::host_winograd::KeptWeights;
use crate::host_winograd::{
    Conv3x3, split_first, split_row, split_second, winograd_conv, winograd_disabled, winograd_variant,
};
use crate::matmul_conv::{conv2d_by_matmul, conv2d_by_matmul_then, matmul_conv_applies};
use crate::tensor::reuse_buffer;

/// Output pixels per tile (whole output rows, at least one): enough columns for an efficient
/// product, few enough for many tiles and small column buffers. 128, 256, 512 and 1024 ran within
/// the noise of each other; 128 needs the least memory (283 against 310 MiB peak at 384x448).
const TILE_PIXELS: usize = 128;

/// Column-matrix elements per tile: shallow columns (few input channels times kernel taps) get
/// more than [`TILE_PIXELS`] pixels, up to the matrix a 3x3 layer of 64 channels has at 128
/// pixels, so their products are fewer and larger. In one process alternating, median ms (min):
/// the motion encoder's 1x1 36->64 at 96x112 1.18 (1.00) -> 0.95 (0.82), its 7x7 2->64 2.06
/// (1.90) -> 1.72 (1.66), the mask head's 1x1 256->144 10.11 (8.25) -> 9.33 (7.38), the 7x7 stem
/// at 384x448 min 34.8 -> 31.0; deep columns (a stride-2 3x3 of 64 channels) unchanged.
const COLUMN_BUDGET: usize = 128 * 576;

/// `conv.forward(x)`: the host kernel for CPU inference, one matrix product for stride-1
/// convolutions in GPU inference ([`crate::matmul_conv`]), burn's convolution elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_forward(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    match conv_options(conv) {
        Some(options) => conv2d_op(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), options),
        None => conv.forward(x),
    }
}

/// `relu(conv.forward(x))`: on CPU inference the host kernel applies the ReLU while it writes
/// the output (no extra pass), elsewhere [`conv2d_forward`] and a ReLU.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_relu_forward(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    match conv_options(conv) {
        Some(options) if host_kernels_apply(&x.device()) => {
            conv2d_host_rectified(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), &options, true)
        }
        _ => conv2d_forward_then(conv, x, burn::tensor::activation::relu),
    }
}

/// [`conv2d_forward`] followed by `then`, element-wise work on the output seen as
/// `[N, O, H_out·W_out]` (see [`conv2d_op_then`]).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, O, H_out, W_out]`
pub fn conv2d_forward_then(conv: &Conv2d, x: Tensor<4>, then: impl FnOnce(Tensor<3>) -> Tensor<3>) -> Tensor<4> {
    match conv_options(conv) {
        Some(options) => conv2d_op_then(x, conv.weight.val(), conv.bias.as_ref().map(|b| b.val()), options, then),
        None => pixels_then(conv.forward(x), then),
    }
}

/// [`conv2d_op`] followed by `then`, element-wise work on the output seen as
/// `[N, O, H_out·W_out]` whose other operands the caller has flattened alike ([`flat_pixels`])
/// before the call. On the GPU's product route `then` runs in the product's own kernel
/// ([`crate::matmul_conv::conv2d_by_matmul_then`]); elsewhere after the convolution.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
/// - `then` maps `[N, O, H_out·W_out]` to the same shape
pub fn conv2d_op_then(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
) -> Tensor<4> {
    let [_, _, kh, kw] = weight.dims();
    match conv_path(&x.device(), &options, [kh, kw]) {
        ConvPath::Product => conv2d_by_matmul_then(x, weight, bias, &options, then),
        ConvPath::Host | ConvPath::Burn => pixels_then(conv2d_op(x, weight, bias, options), then),
    }
}

/// `x` (`[N, C, H, W]`) as `[N, C, H·W]`, the shape [`conv2d_op_then`]'s `then` works on.
pub fn flat_pixels(x: Tensor<4>) -> Tensor<3> {
    let [n, c, h, w] = x.dims();
    x.reshape([n, c, h * w])
}

/// `then` on `x` seen as `[N, C, H·W]`, the result as `[N, C, H, W]`.
fn pixels_then(x: Tensor<4>, then: impl FnOnce(Tensor<3>) -> Tensor<3>) -> Tensor<4> {
    let dims = x.dims();
    then(flat_pixels(x)).reshape(dims)
}

/// What the host convolution does to each output value after adding the bias.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Epilogue {
    /// Nothing.
    Linear,
    /// `max(0, ·)`.
    Relu,
}

/// The options of `conv` as the host kernel takes them; `None` for what it does not do (groups,
/// `Same` padding, which depends on the input size).
pub fn conv_options(conv: &Conv2d) -> Option<ConvOptions<2>> {
    let padding = match conv.padding {
        PaddingConfig2d::Explicit(top, left, bottom, right) => [(top, bottom), (left, right)],
        PaddingConfig2d::Valid => [(0, 0), (0, 0)],
        PaddingConfig2d::Same => return None,
    };
    (conv.groups == 1).then(|| ConvOptions::new_with_padding(conv.stride, padding, conv.dilation, 1))
}

/// burn's `conv2d(x, weight, bias, options)` as [`conv2d_forward`] chooses: the host kernel for
/// CPU inference (groups = 1), one matrix product for stride-1 convolutions in GPU inference
/// ([`crate::matmul_conv`]), burn's operation elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`; output `[N, O, H_out, W_out]`
pub fn conv2d_op(x: Tensor<4>, weight: Tensor<4>, bias: Option<Tensor<1>>, options: ConvOptions<2>) -> Tensor<4> {
    let [_, _, kh, kw] = weight.dims();
    match conv_path(&x.device(), &options, [kh, kw]) {
        ConvPath::Host => conv2d_host(x, weight, bias, &options),
        ConvPath::Product => conv2d_by_matmul(x, weight, bias, &options),
        ConvPath::Burn => conv2d(x, weight, bias, options),
    }
}

/// Where [`conv2d_op`] and [`conv2d_op_then`] compute a convolution.
enum ConvPath {
    /// The host kernel (CPU inference, groups 1).
    Host,
    /// One matrix product ([`crate::matmul_conv`], GPU inference).
    Product,
    /// burn's operation.
    Burn,
}

/// The [`ConvPath`] of a convolution with `options` and a `kh x kw` kernel on `device`.
fn conv_path(device: &Device, options: &ConvOptions<2>, kernel: [usize; 2]) -> ConvPath {
    if options.groups == 1 && host_kernels_apply(device) {
        ConvPath::Host
    } else if matmul_conv_applies(device, options, kernel) {
        ConvPath::Product
    } else {
        ConvPath::Burn
    }
}

/// `conv2d(x, weight, bias)` with `options` (groups = 1), computed on the host.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`
/// - output: `[N, O, H_out, W_out]` with `H_out = (H + 2·pad - dil·(kh - 1) - 1) / stride + 1`
pub fn conv2d_host(x: Tensor<4>, weight: Tensor<4>, bias: Option<Tensor<1>>, options: &ConvOptions<2>) -> Tensor<4> {
    conv2d_host_rectified(x, weight, bias, options, false)
}

/// [`conv2d_host`], rectified (`relu`) as the output is written when `relu`.
///
/// # Shapes
/// - as [`conv2d_host`]
pub fn conv2d_host_rectified(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
    relu: bool,
) -> Tensor<4> {
    let epilogue = if relu { Epilogue::Relu } else { Epilogue::Linear };
    on_host_buffers(x, weight, bias, |x, x_dims, wt, w_dims, bias| {
        host_conv_slices(x, x_dims, wt, w_dims, bias, options, epilogue)
    })
}

/// [`conv2d_host`] by the im2col path alone, never Winograd: for benchmarks and tests that
/// compare the two paths.
///
/// # Shapes
/// - as [`conv2d_host`]
pub fn conv2d_host_im2col(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
) -> Tensor<4> {
    on_host_buffers(x, weight, bias, |x, x_dims, wt, w_dims, bias| {
        im2col_conv_slices(x, x_dims, wt, w_dims, bias, options, Epilogue::Linear)
    })
}

/// Runs `conv` (a convolution on host buffers: input, its dims, weight, its dims, bias) on the
/// tensors' values and returns its output as a tensor on the input's device.
fn on_host_buffers(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    conv: impl FnOnce(&[f32], [usize; 4], &[f32], [usize; 4], Option<&[f32]>) -> (Vec<f32>, [usize; 4]),
) -> Tensor<4> {
    let device: Device = x.device();
    let (x_dims, w_dims) = (x.dims(), weight.dims());
    let (x, wt) = (crate::tensor::host_values(x), crate::tensor::host_values(weight));
    let bias = bias.map(crate::tensor::host_values);
    let (out, dims) = conv(&x, x_dims, &wt, w_dims, bias.as_deref());
    Tensor::from_data(TensorData::new(out, dims), &device)
}

/// [`conv2d_host`] on host buffers (row-major NCHW input, OIHW weight), for kernels that chain
/// several steps without going through tensors. Returns the output and its dimensions.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `weight`: `w_dims = [O, C, kh, kw]`; `bias`: `[O]`
pub fn conv2d_host_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
) -> (Vec<f32>, [usize; 4]) {
    host_conv_slices(x, x_dims, wt, w_dims, bias, options, Epilogue::Linear)
}

/// The second of two host convolutions that share input channels, waiting for the rest of its
/// input ([`conv2d_host_shared_first`]).
pub struct PendingConv(crate::host_winograd::Pending);

/// Two 3x3 convolutions whose inputs share channels, the shared ones transformed once (the
/// ConvGRU's gates over `[h, x]` and candidate over `[r·h, x]`, module `host_winograd`'s
/// `split`): returns the first convolution's output (weight `wt_first` over all of `x`, bias
/// `bias_first`) and the second's products over the shared channels, the last `shared` of `x`
/// and of the second's input, whose weight `wt_second` has `c2` input channels. `None` (nothing
/// computed) where the Winograd path would not run both convolutions.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `wt_first`: `[O1, C, 3, 3]`; `wt_second`: `[O2, c2, 3, 3]`
/// - output (returned without its dimensions) `[N, O1, H_out, W_out]`
#[allow(clippy::too_many_arguments)]
pub fn conv2d_host_shared_first(
    x: &[f32],
    x_dims: [usize; 4],
    [wt_first, wt_second]: [&[f32]; 2],
    [o1, o2]: [usize; 2],
    c2: usize,
    shared: usize,
    bias_first: Option<&[f32]>,
    options: &ConvOptions<2>,
) -> Option<(Vec<f32>, PendingConv)> {
    let [n, c, h, w] = x_dims;
    let variant = winograd_variant(x_dims, [o1, c, 3, 3], options)
        .filter(|_| winograd_variant([n, c2, h, w], [o2, c2, 3, 3], options).is_some() && !winograd_disabled())?;
    check_shapes(x, x_dims, wt_first, [o1, c, 3, 3], options);
    let (out, pending) = split_first(
        variant,
        x,
        x_dims,
        [wt_first, wt_second],
        [o1, o2],
        c2,
        shared,
        bias_first,
        options.padding,
        Epilogue::Linear,
    );
    Some((out.0, PendingConv(pending)))
}

/// The second convolution of [`conv2d_host_shared_first`]: its own input channels `x` (the first
/// `c2 - shared`), with its bias.
///
/// # Shapes
/// - `x`: `x_dims = [N, c2 - shared, H, W]`; output `[N, O2, H_out, W_out]`
pub fn conv2d_host_shared_second(
    pending: PendingConv,
    x: &[f32],
    x_dims: [usize; 4],
    bias: Option<&[f32]>,
) -> (Vec<f32>, [usize; 4]) {
    split_second(pending.0, x, x_dims, bias, Epilogue::Linear)
}

/// [`conv2d_host_slices`] with an epilogue: Winograd F(4x4, 3x3) or F(2x2, 3x3) for the 3x3
/// stride-1 convolutions they suit ([`crate::host_winograd`]), im2col tiles otherwise.
fn host_conv_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    if let Some(variant) = winograd_variant(x_dims, w_dims, options).filter(|_| !winograd_disabled()) {
        check_shapes(x, x_dims, wt, w_dims, options);
        let conv = Conv3x3 { x, x_dims, wt, o: w_dims[0], bias, padding: options.padding, epilogue };
        return winograd_conv(variant, &conv);
    }
    if host_few_outputs::suits(x_dims[1], w_dims[0], options.stride, options.groups) {
        check_shapes(x, x_dims, wt, w_dims, options);
        return few_outputs_conv(x, x_dims, wt, w_dims, bias, options.padding, options.dilation, epilogue);
    }
    im2col_conv_slices(x, x_dims, wt, w_dims, bias, options, epilogue)
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

/// The `[H_out, W_out]` of a convolution of an `[h, w]` input with a `[kh, kw]` kernel and
/// `options`; panics, naming `caller`, where the padded input is smaller than the dilated kernel.
pub(crate) fn conv_output_size(
    caller: &str,
    [h, w]: [usize; 2],
    [kh, kw]: [usize; 2],
    options: &ConvOptions<2>,
) -> [usize; 2] {
    let [(ph, ph_end), (pw, pw_end)] = options.padding;
    let [dh, dw] = options.dilation;
    let (reach_h, reach_w) = (dh * (kh - 1) + 1, dw * (kw - 1) + 1);
    assert!(
        h + ph + ph_end >= reach_h && w + pw + pw_end >= reach_w,
        "{caller}: a {h}x{w} input with padding {:?} is smaller than the {reach_h}x{reach_w} kernel",
        options.padding
    );
    let [sh, sw] = options.stride;
    [(h + ph + ph_end - reach_h) / sh + 1, (w + pw + pw_end - reach_w) / sw + 1]
}

/// `out` (images of `o` output planes of `plane` values each) cut into parallel jobs of one image
/// and one band of `band_len` values of every plane: job `image·bands + band` holds that band's
/// slice of each of the image's planes, in plane order (the last band may be shorter).
pub(crate) fn band_jobs<T>(out: &mut [T], o: usize, plane: usize, band_len: usize) -> Vec<Vec<&mut [T]>> {
    let bands = plane.div_ceil(band_len);
    let images = out.len() / (o * plane).max(1);
    let mut jobs: Vec<Vec<&mut [T]>> = (0..images * bands).map(|_| Vec::with_capacity(o)).collect();
    for (i, dst) in out.chunks_mut(plane).enumerate() {
        for (band, rows) in dst.chunks_mut(band_len).enumerate() {
            jobs[(i / o) * bands + band].push(rows);
        }
    }
    jobs
}

/// [`host_conv_slices`] by im2col tiles and `gemm` for any shape (the path for everything the
/// Winograd path does not take; the tests call it directly).
pub(crate) fn im2col_conv_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    let [out_h, out_w] = check_shapes(x, x_dims, wt, w_dims, options);
    let [n, c, h, w] = x_dims;
    let [o, _, kh, kw] = w_dims;
    let [sh, sw] = options.stride;
    let [(ph, _), (pw, _)] = options.padding;
    let [dh, dw] = options.dilation;
    let k = c * kh * kw;
    let plane = out_h * out_w;
    let tile_pixels = (COLUMN_BUDGET / k.max(1)).max(TILE_PIXELS);
    let rows_per_tile = (tile_pixels / out_w.max(1)).clamp(1, out_h.max(1));
    let tiles_per_image = out_h.div_ceil(rows_per_tile);
    let geometry = Geometry { c, h, w, kh, kw, sh, sw, ph, pw, dh, dw, out_w };

    // One job per (image, tile of output rows) with its rows of every output plane; its O x P
    // product goes to the thread's block buffer, then into those rows with the bias and the
    // epilogue (no per-tile allocation, no second pass over the whole output).
    let mut out = crate::tensor::zeros_parallel(n * o * plane);
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
            fill_columns(col, &x[b * c * h * w..(b + 1) * c * h * w], geometry, oy0..oy1);
            matmul_into(block, wt, k, col, [o, p, k]);
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

/// `dst = lhs · rhs` on the calling thread by the `gemm` crate: `dst` is `rows x cols` (row
/// stride `cols`), `lhs` `rows x depth` (row stride `lhs_stride`), `rhs` `depth x cols`.
pub(crate) fn matmul_into(
    dst: &mut [f32],
    lhs: &[f32],
    lhs_stride: usize,
    rhs: &[f32],
    [rows, cols, depth]: [usize; 3],
) {
    matmul_strided(dst, cols, lhs, lhs_stride, rhs, cols, [rows, cols, depth]);
}

/// [`matmul_into`] with row strides for all three: `dst` `rows x cols` (row stride
/// `dst_stride`), `lhs` `rows x depth` (`lhs_stride`), `rhs` `depth x cols` (`rhs_stride`).
pub(crate) fn matmul_strided(
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

/// [`matmul_strided`], or `dst += lhs · rhs` (adding to what `dst` holds) when `accumulate`:
/// the one call of the `gemm` crate.
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul_strided_with(
    dst: &mut [f32],
    dst_stride: usize,
    lhs: &[f32],
    lhs_stride: usize,
    rhs: &[f32],
    rhs_stride: usize,
    [rows, cols, depth]: [usize; 3],
    accumulate: bool,
) {
    // The last row of each operand reaches `(rows - 1)·stride + width` elements.
    let reach = |count: usize, stride: usize, width: usize| count.checked_sub(1).map_or(0, |c| c * stride + width);
    assert!(cols <= dst_stride && cols <= rhs_stride && depth <= lhs_stride);
    assert!(dst.len() >= reach(rows, dst_stride, cols) && rhs.len() >= reach(depth, rhs_stride, cols));
    assert!(lhs.len() >= reach(rows, lhs_stride, depth));
    // SAFETY: the asserts keep every element the strides reach inside the three slices, which
    // live through the call; `dst` is read (when `accumulate`) and written only there.
    #[rustfmt::skip]
    unsafe {
        gemm::gemm(rows, cols, depth, dst.as_mut_ptr(), 1, dst_stride as isize, accumulate,
                   lhs.as_ptr(), 1, lhs_stride as isize, rhs.as_ptr(), 1, rhs_stride as isize,
                   if accumulate { 1.0f32 } else { 0.0 }, 1.0f32, false, false, false, gemm::Parallelism::None);
    };
}

thread_local! {
    /// Each worker thread's column matrix and product block, grown to the largest tile it has
    /// built.
    static COLUMNS: std::cell::RefCell<[Vec<f32>; 2]> = const { std::cell::RefCell::new([Vec::new(), Vec::new()]) };
}

/// Sizes of one convolution: input channels and size, kernel, stride, leading padding,
/// dilation, output width.
#[derive(Clone, Copy)]
struct Geometry {
    c: usize,
    h: usize,
    w: usize,
    kh: usize,
    kw: usize,
    sh: usize,
    sw: usize,
    ph: usize,
    pw: usize,
    dh: usize,
    dw: usize,
    out_w: usize,
}

/// Writes every element of the column matrix of output rows `rows` of one image (`src`, NCHW).
fn fill_columns(col: &mut [f32], src: &[f32], g: Geometry, rows: std::ops::Range<usize>) {
    if g.sw == 2 {
        return fill_columns_stride2(col, src, g, rows);
    }
    let p = rows.len() * g.out_w;
    for ci in 0..g.c {
        let channel = &src[ci * g.h * g.w..(ci + 1) * g.h * g.w];
        for ky in 0..g.kh {
            for kx in 0..g.kw {
                let row = &mut col[((ci * g.kh + ky) * g.kw + kx) * p..][..p];
                let offset = (kx * g.dw) as isize - g.pw as isize;
                for (r, oy) in rows.clone().enumerate() {
                    let dst = &mut row[r * g.out_w..][..g.out_w];
                    let iy = (oy * g.sh + ky * g.dh) as isize - g.ph as isize;
                    if iy < 0 || iy >= g.h as isize {
                        dst.fill(0.0);
                        continue;
                    }
                    let line = &channel[iy as usize * g.w..][..g.w];
                    if g.sw == 1 {
                        // ix = ox + offset: one shifted copy, zeros outside the input.
                        shifted_copy(dst, line, offset);
                    } else {
                        for (ox, v) in dst.iter_mut().enumerate() {
                            let ix = (ox * g.sw) as isize + offset;
                            *v = if ix >= 0 && ix < g.w as isize { line[ix as usize] } else { 0.0 };
                        }
                    }
                }
            }
        }
    }
}

/// [`fill_columns`] for a horizontal stride of 2: each input row a kernel row reads is split
/// into its even and odd columns (module `host_winograd`'s row split), and every kernel column's
/// row of the matrix is then one shifted copy from one of them (column `2·ox + offset` is phase
/// `offset mod 2`, index `ox + offset div 2`). The general path gathered element by element,
/// once per kernel column: the encoders' stride-2 convolutions spent most of their
/// column-building time there.
fn fill_columns_stride2(col: &mut [f32], src: &[f32], g: Geometry, rows: std::ops::Range<usize>) {
    let p = rows.len() * g.out_w;
    // Both phases `ceil(w / 2)` long: for an odd width the odd phase's last value lies outside
    // the row, a zero like the padding.
    let half = g.w.div_ceil(2);
    let mut phases = vec![0.0f32; 2 * half];
    for ci in 0..g.c {
        let channel = &src[ci * g.h * g.w..(ci + 1) * g.h * g.w];
        for ky in 0..g.kh {
            for (r, oy) in rows.clone().enumerate() {
                let iy = (oy * g.sh + ky * g.dh) as isize - g.ph as isize;
                let inside = iy >= 0 && iy < g.h as isize;
                if inside {
                    let (even, odd) = phases.split_at_mut(half);
                    split_row::<2>(&channel[iy as usize * g.w..][..g.w], 0, [even, odd]);
                }
                for kx in 0..g.kw {
                    let dst = &mut col[((ci * g.kh + ky) * g.kw + kx) * p + r * g.out_w..][..g.out_w];
                    if !inside {
                        dst.fill(0.0);
                        continue;
                    }
                    let offset = (kx * g.dw) as isize - g.pw as isize;
                    let (phase, shift) = (offset.rem_euclid(2) as usize, offset.div_euclid(2));
                    shifted_copy(dst, &phases[phase * half..][..half], shift);
                }
            }
        }
    }
}

/// `dst[i] = source[i + shift]` where that index lies inside `source`, zeros elsewhere.
fn shifted_copy(dst: &mut [f32], source: &[f32], shift: isize) {
    let n = dst.len() as isize;
    let lo = (-shift).clamp(0, n) as usize;
    let hi = (source.len() as isize - shift).clamp(lo as isize, n) as usize;
    let start = (lo as isize + shift) as usize;
    dst[..lo].fill(0.0);
    dst[lo..hi].copy_from_slice(&source[start..start + (hi - lo)]);
    dst[hi..].fill(0.0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;

    use crate::tensor::to_vec;

    #[allow(clippy::too_many_arguments)]
    fn case(n: usize, c: usize, o: usize, hw: [usize; 2], k: [usize; 2], stride: usize, pad: [usize; 2], dil: usize) {
        let device = Device::flex();
        let x = Tensor::<4>::random([n, c, hw[0], hw[1]], Distribution::Normal(0.0, 1.0), &device);
        let wt = Tensor::<4>::random([o, c, k[0], k[1]], Distribution::Normal(0.0, 0.2), &device);
        let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
        let options = ConvOptions::new([stride, stride], pad, [dil, dil], 1);
        let stock = conv2d(x.clone(), wt.clone(), Some(b.clone()), options.clone());
        let host = conv2d_host(x.clone(), wt.clone(), Some(b.clone()), &options);
        assert_eq!(stock.dims(), host.dims());
        // Relative to the output's largest magnitude: Winograd F(4x4) (taken from 128 tiles)
        // errs by up to ~1e-5 of it, which in absolute terms depends on the random draw.
        let scale = stock.clone().abs().max().into_scalar::<f32>().max(1.0);
        let diff = crate::tensor::max_abs_diff(stock.clone(), host) / scale;
        assert!(diff < 4e-5, "n {n} c {c} o {o} {hw:?} k {k:?} s {stride} p {pad:?} d {dil}: {diff}");
        // Without a bias: the stock result minus the bias it added.
        let unbiased = conv2d_host(x, wt, None, &options);
        let diff = crate::tensor::max_abs_diff(stock - b.reshape([1, o as i32, 1, 1]), unbiased) / scale;
        assert!(diff < 4e-5, "no bias: n {n} c {c} o {o} {hw:?} k {k:?}: {diff}");
    }

    #[test]
    fn module_forward_takes_the_host_kernel_only_for_cpu_inference() {
        use burn::module::Module;
        use burn::nn::conv::Conv2dConfig;
        let device = Device::flex();
        let conv = Conv2dConfig::new([4, 6], [3, 3]).with_padding(PaddingConfig2d::Explicit(1, 2, 1, 2)).init(&device);
        let x = Tensor::<4>::random([1, 4, 10, 12], Distribution::Normal(0.0, 1.0), &device);
        let diff = crate::tensor::max_abs_diff(conv.forward(x.clone()), conv2d_forward(&conv, x.clone()));
        assert!(diff < 1e-5, "{diff}");
        // With autodiff the stock operation runs and gradients flow.
        let ad = device.autodiff();
        let conv_ad = conv.fork(&ad).train();
        let y = conv2d_forward(&conv_ad, Tensor::from_data(x.into_data(), &ad)).sum();
        let grads = y.backward();
        assert!(conv_ad.weight.grad(&grads).is_some());
    }

    #[test]
    fn the_relu_epilogue_equals_relu_after_the_convolution() {
        use burn::module::Module;
        use burn::nn::conv::Conv2dConfig;
        let device = Device::flex();
        let conv = Conv2dConfig::new([5, 7], [3, 3]).with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1)).init(&device);
        let x = Tensor::<4>::random([2, 5, 9, 11], Distribution::Normal(0.0, 1.0), &device);
        let expected = burn::tensor::activation::relu(conv.forward(x.clone()));
        let host = conv2d_relu_forward(&conv, x.clone());
        assert!(crate::tensor::max_abs_diff(expected.clone(), host.clone()) < 1e-5);
        assert!(to_vec(host).contains(&0.0), "a random convolution has negative outputs");
        // The stock path (autodiff) too.
        let ad = device.clone().autodiff();
        let stock = conv2d_relu_forward(&conv.fork(&ad), Tensor::from_data(x.into_data(), &ad));
        assert!(crate::tensor::max_abs_diff(expected, Tensor::from_data(stock.into_data(), &device)) < 1e-5);
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
        assert_eq!(winograd_variant([2, 48, 20, 17], [40, 48, 3, 3], &options).map(|v| v.m), Some(2));
        assert_eq!(
            winograd_variant([1, 32, 46, 49], [64, 32, 3, 3], &ConvOptions::new([1, 1], [0, 0], [1, 1], 1))
                .map(|v| v.m),
            Some(4)
        );
        case(2, 48, 40, [20, 17], [3, 3], 1, [1, 1], 1);
        case(1, 32, 64, [46, 49], [3, 3], 1, [0, 0], 1);
    }

    #[test]
    fn the_dispatch_takes_winograd_for_3x3_stride_1_with_many_channels() {
        let options = |stride, dilation, padding| ConvOptions::new([stride, stride], [padding; 2], [dilation; 2], 1);
        let variant = |x, w, options: &ConvOptions<2>| winograd_variant(x, w, options).map(|v| v.m);
        assert_eq!(variant([1, 384, 96, 112], [128, 384, 3, 3], &options(1, 1, 1)), Some(4));
        assert_eq!(variant([1, 32, 16, 16], [32, 32, 3, 3], &options(1, 1, 1)), Some(2), "the smallest: 64 tiles");
        assert_eq!(variant([4, 32, 8, 8], [32, 32, 3, 3], &options(1, 1, 1)), Some(2), "64 tiles over the batch");
        let side = 4 * (crate::host_winograd::MIN_F4_TILES as f64).sqrt().ceil() as usize;
        assert_eq!(variant([1, 64, side, side], [64, 64, 3, 3], &options(1, 1, 1)), Some(4), "enough 4x4 tiles");
        assert_eq!(variant([1, 64, side - 8, side], [64, 64, 3, 3], &options(1, 1, 1)), Some(2), "too few");
        let none = [
            ([1, 32, 16, 14], [32, 32, 3, 3], options(1, 1, 1)), // 56 tiles
            ([1, 32, 18, 16], [32, 32, 3, 3], options(1, 1, 0)), // 56 tiles unpadded
            ([1, 384, 96, 112], [128, 384, 3, 3], options(2, 1, 1)),
            ([1, 384, 96, 112], [128, 384, 3, 3], options(1, 2, 2)),
            ([1, 384, 96, 112], [128, 384, 1, 1], options(1, 1, 0)),
            ([1, 64, 96, 112], [64, 64, 7, 7], options(1, 1, 3)),
            ([1, 3, 96, 112], [64, 3, 3, 3], options(1, 1, 1)),
            ([1, 128, 96, 112], [2, 128, 3, 3], options(1, 1, 1)),
            ([1, 16, 96, 112], [16, 16, 3, 3], options(1, 1, 1)),
            ([1, 64, 1, 1], [64, 64, 3, 3], options(1, 1, 1)),
            ([1, 64, 96, 112], [64, 32, 3, 3], ConvOptions::new([1, 1], [1, 1], [1, 1], 2)),
        ];
        for (x, w, options) in none {
            assert_eq!(variant(x, w, &options), None, "{x:?} {w:?} {options:?}");
        }
    }

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
