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

use super::few_outputs::{few_outputs_conv, suits as few_outputs_suit};
use super::winograd::{Conv3x3, Pending, split_first, split_row, split_second, winograd_conv, winograd_variant};
use crate::geometry::{Epilogue, band_jobs, conv_output_size};
use crate::product::matmul_into;
use crate::settings::settings;

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
    let (x, wt) = (host_values(x), host_values(weight));
    let bias = bias.map(host_values);
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
pub struct PendingConv(Pending);

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
        .filter(|_| winograd_variant([n, c2, h, w], [o2, c2, 3, 3], options).is_some() && settings().winograd)?;
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
/// stride-1 convolutions they suit ([`super::winograd`]), im2col tiles otherwise.
fn host_conv_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    if let Some(variant) = winograd_variant(x_dims, w_dims, options).filter(|_| settings().winograd) {
        check_shapes(x, x_dims, wt, w_dims, options);
        let conv = Conv3x3 { x, x_dims, wt, o: w_dims[0], bias, padding: options.padding, epilogue };
        return winograd_conv(variant, &conv);
    }
    direct_conv_slices(x, x_dims, wt, w_dims, bias, options, epilogue)
}

/// [`conv2d_host_slices`] without Winograd: the few-output kernel or im2col tiles, whose sums
/// are the plain products' (the training forward takes these below 256 input channels:
/// Winograd's transforms round differently, and the feature encoder's instance norms magnify a
/// different rounding of their inputs past the official training step's check; the GRUs' wider
/// convolutions and the input gradient may take Winograd).
///
/// # Shapes
/// - as [`conv2d_host_slices`]
pub fn conv2d_host_direct_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
) -> (Vec<f32>, [usize; 4]) {
    direct_conv_slices(x, x_dims, wt, w_dims, bias, options, Epilogue::Linear)
}

/// The few-output kernel where it suits, im2col tiles otherwise.
fn direct_conv_slices(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    bias: Option<&[f32]>,
    options: &ConvOptions<2>,
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    if few_outputs_suit(x_dims[1], w_dims[0], options.stride, options.groups) {
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

/// Writes the column matrix (`K x P` row-major: row `(c, ky, kx)`, column the output pixel) of
/// output rows `rows` of one image `x` (`[C, H, W]`) for a `kh x kw` kernel with `options`, whose
/// output is `out_w` wide: the im2col path's columns, for the weight gradient.
pub(crate) fn image_columns(
    col: &mut [f32],
    x: &[f32],
    [c, h, w]: [usize; 3],
    [kh, kw]: [usize; 2],
    options: &ConvOptions<2>,
    out_w: usize,
    rows: std::ops::Range<usize>,
) {
    let [sh, sw] = options.stride;
    let [(ph, _), (pw, _)] = options.padding;
    let [dh, dw] = options.dilation;
    fill_columns(col, x, Geometry { c, h, w, kh, kw, sh, sw, ph, pw, dh, dw, out_w }, rows);
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
    use burn::tensor::Distribution;
    use burn::tensor::module::conv2d;

    use super::*;
    use dgstereo_core::tensor::max_abs_diff;

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
        let diff = max_abs_diff(stock.clone(), host) / scale;
        assert!(diff < 4e-5, "n {n} c {c} o {o} {hw:?} k {k:?} s {stride} p {pad:?} d {dil}: {diff}");
        // Without a bias: the stock result minus the bias it added.
        let unbiased = conv2d_host(x, wt, None, &options);
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
        let side = 4 * (super::super::winograd::MIN_F4_TILES as f64).sqrt().ceil() as usize;
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
}
