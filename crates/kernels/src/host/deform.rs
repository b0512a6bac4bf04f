//! The deformable convolution of DGIA on host buffers, for CPU inference (`crate::ops::deform`).
//!
//! Design decision: burn Flex's `deform_conv2d` builds a deformable im2col matrix on one thread per
//! image (its only parallel loop is over the batch, and the model fuses one view at a time),
//! recomputing the bilinear sampling position and weights for every input channel and writing the
//! matrix with a stride of the whole image between consecutive values; at the full network
//! resolution it took about a third of the paper model's CPU inference. DGIA's deformable
//! convolution has few channels (`2F = 16` in, 3 out), so here every output pixel accumulates its
//! outputs directly: the input is laid out with its channels innermost once, per kernel tap the
//! sampling position, its four corners and their weights are found once and the sample of all
//! channels is one vector, which goes straight into per-output-channel partial sums; rows of output
//! pixels run in parallel. Used where the host kernels apply (CPU inference,
//! the dispatch's host path) and the convolution has one weight group, one
//! offset group and no modulation mask (DGIA's); burn's operation stays the reference and the path
//! everywhere else, and the tests check both agree.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::DeformConv2d;
use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::host_values;
use rayon::prelude::*;

/// The geometry of one deformable convolution: input channels and size, output channels,
/// kernel, stride, padding, dilation, output size.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    pub(crate) c: usize,
    pub(crate) o: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) kh: usize,
    pub(crate) kw: usize,
    pub(crate) stride: [usize; 2],
    pub(crate) padding: [usize; 2],
    pub(crate) dilation: [usize; 2],
    pub(crate) out_h: usize,
    pub(crate) out_w: usize,
}

/// Stride, symmetric padding and dilation of a deformable convolution with one weight and one
/// offset group and no modulation mask: the convolutions the host kernels take.
#[derive(Clone, Copy, Debug)]
pub struct DeformOptions {
    /// Stride `[rows, columns]`.
    pub stride: [usize; 2],
    /// Padding on each side `[rows, columns]`.
    pub padding: [usize; 2],
    /// Dilation `[rows, columns]`.
    pub dilation: [usize; 2],
}

impl DeformOptions {
    /// `conv`'s options, or `None` where the host kernels do not take it (several weight or
    /// offset groups, padding other than explicit and symmetric or none).
    pub fn of(conv: &DeformConv2d) -> Option<Self> {
        if conv.weight_groups != 1 || conv.offset_groups != 1 {
            return None;
        }
        let padding = match conv.padding {
            PaddingConfig2d::Valid => [0, 0],
            PaddingConfig2d::Explicit(top, left, bottom, right) if top == bottom && left == right => [top, left],
            _ => return None,
        };
        Some(Self { stride: conv.stride, padding, dilation: conv.dilation })
    }
}

impl Geometry {
    /// The geometry of an input `[_, C, H, W]` and a weight `[O, C, kh, kw]` under `options`, or
    /// `None` where the kernel does not fit the padded input.
    pub(crate) fn new(
        [_, c, h, w]: [usize; 4],
        [o, _, kh, kw]: [usize; 4],
        DeformOptions { stride, padding, dilation }: DeformOptions,
    ) -> Option<Self> {
        let extent = |size: usize, axis: usize, k: usize| {
            (size + 2 * padding[axis]).checked_sub(dilation[axis] * (k - 1) + 1).map(|span| span / stride[axis] + 1)
        };
        let (out_h, out_w) = (extent(h, 0, kh)?, extent(w, 1, kw)?);
        Some(Self { c, o, h, w, kh, kw, stride, padding, dilation, out_h, out_w })
    }
}

/// `conv`'s output for `input` sampled at `offset`, or `None` where this kernel does not apply
/// (several weight or offset groups, padding other than explicit and symmetric or none).
///
/// # Shapes
/// - `input`: `[N, C, H, W]`; `offset`: `[N, 2·kh·kw, H_out, W_out]` (per kernel tap `k =
///   kh_i·kw + kw_i`, channel `2k` the row offset, `2k + 1` the column offset, as torchvision)
/// - output: `[N, O, H_out, W_out]`
pub fn deform_conv2d_host(conv: &DeformConv2d, input: Tensor<4>, offset: Tensor<4>) -> Option<Tensor<4>> {
    let options = DeformOptions::of(conv)?;
    let device = input.device();
    let [n, c, h, w] = input.dims();
    let w_dims = conv.weight.dims();
    let g = Geometry::new([n, c, h, w], w_dims, options)?;
    assert_eq!(
        w_dims[1], c,
        "deformable convolution: the weight takes {} input channels, the input has {c}",
        w_dims[1]
    );
    assert_eq!(
        offset.dims(),
        [n, 2 * g.kh * g.kw, g.out_h, g.out_w],
        "deformable convolution: offsets must be [N, 2·kh·kw, H_out, W_out]"
    );
    let bias = conv.bias.as_ref().map(|b| host_values(b.val()));
    let out = deform_slices(
        &host_values(input),
        n,
        &host_values(offset),
        &host_values(conv.weight.val()),
        bias.as_deref(),
        g,
    );
    Some(Tensor::from_data(TensorData::new(out, [n, g.o, g.out_h, g.out_w]), &device))
}

/// The input with its channels innermost, `[N][H·W][C]`, so that a sample of all channels at
/// one position is one contiguous run.
pub(crate) fn channels_innermost(x: &[f32], n: usize, g: Geometry) -> Vec<f32> {
    let (c, h, w) = (g.c, g.h, g.w);
    let plane_in = h * w;
    let mut pixels = vec![0f32; n * plane_in * c];
    pixels.par_chunks_mut(w * c).enumerate().for_each(|(row, dst)| {
        let (b, y) = (row / h, row % h);
        for (ic, channel) in x[b * c * plane_in..][..c * plane_in].chunks_exact(plane_in).enumerate() {
            for (xx, &value) in channel[y * w..][..w].iter().enumerate() {
                dst[xx * c + ic] = value;
            }
        }
    });
    pixels
}

/// The weight `[O, C, kh, kw]` per tap and output channel, the input channels innermost:
/// `[k][O][C]`.
pub(crate) fn weight_per_tap(weight: &[f32], g: Geometry) -> Vec<f32> {
    let (o, c, taps_n) = (g.o, g.c, g.kh * g.kw);
    let mut taps = vec![0f32; taps_n * o * c];
    for (oc, per_out) in weight.chunks_exact(c * taps_n).enumerate() {
        for (ic, per_in) in per_out.chunks_exact(taps_n).enumerate() {
            for (k, &value) in per_in.iter().enumerate() {
                taps[(k * o + oc) * c + ic] = value;
            }
        }
    }
    taps
}

/// The deformable convolution of `n` images `x` (`[N, C, H, W]`) sampled at `offset` (`[N,
/// 2·kh·kw, H_out, W_out]`) with `weight` (`[O, C, kh, kw]`) and `bias` (`[O]`): `[N, O, H_out,
/// W_out]`, rows of output pixels in parallel.
pub(crate) fn deform_slices(
    x: &[f32],
    n: usize,
    offset: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
    g: Geometry,
) -> Vec<f32> {
    let (c, o, kh, kw, out_h, out_w) = (g.c, g.o, g.kh, g.kw, g.out_h, g.out_w);
    let plane_in = g.h * g.w;
    let pixels = channels_innermost(x, n, g);
    let taps = weight_per_tap(weight, g);
    let plane = out_h * out_w;
    let rows: Vec<Vec<f32>> = (0..n * out_h)
        .into_par_iter()
        .map(|job| {
            let (b, oy) = (job / out_h, job % out_h);
            let image = &pixels[b * plane_in * c..][..plane_in * c];
            let offsets = &offset[b * 2 * kh * kw * plane..][..2 * kh * kw * plane];
            match (c, o) {
                (16, 3) => output_row_fixed::<16, 3>(g, image, offsets, &taps, bias, oy),
                (8, 3) => output_row_fixed::<8, 3>(g, image, offsets, &taps, bias, oy),
                _ => output_row(g, image, offsets, &taps, bias, oy),
            }
        })
        .collect();
    let mut out = vec![0f32; n * o * plane];
    for (job, row) in rows.iter().enumerate() {
        let (b, oy) = (job / out_h, job % out_h);
        for (oc, values) in row.chunks_exact(out_w).enumerate() {
            out[(b * o + oc) * plane + oy * out_w..][..out_w].copy_from_slice(values);
        }
    }
    out
}

/// Output row `oy` of one image (`image` as `[H·W][C]`), `[O][W_out]`: bias plus, per output
/// pixel, kernel tap and input channel, the tap's weight times the input sampled bilinearly at
/// the tap's position moved by its offset (zero outside the input, as burn's and torchvision's
/// kernels). Per tap the sample of all channels is one vector, and each output channel keeps a
/// vector of partial sums over the channels, added up once per pixel.
fn output_row(g: Geometry, image: &[f32], offsets: &[f32], taps: &[f32], bias: Option<&[f32]>, oy: usize) -> Vec<f32> {
    let (c, o) = (g.c, g.o);
    let mut row = vec![0f32; o * g.out_w];
    let mut sample = vec![0f32; c];
    let mut partial = vec![0f32; o * c];
    for ox in 0..g.out_w {
        partial.fill(0.0);
        for_each_tap(g, offsets, oy, ox, |k, corners| {
            corners.sample(image, &mut sample);
            for (sums, weights) in partial.chunks_exact_mut(c).zip(taps[k * o * c..][..o * c].chunks_exact(c)) {
                for j in 0..c {
                    sums[j] += weights[j] * sample[j];
                }
            }
        });
        for (oc, sums) in partial.chunks_exact(c).enumerate() {
            row[oc * g.out_w + ox] = bias.map_or(0.0, |b| b[oc]) + sums.iter().sum::<f32>();
        }
    }
    row
}

/// [`output_row`] with the channel counts known at compile time (DGIA's 16 or 8 in, 3 out): the
/// sample and the partial sums live in registers and the per-channel loops unroll into vector
/// operations. Same operations in the same order.
fn output_row_fixed<const C: usize, const O: usize>(
    g: Geometry,
    image: &[f32],
    offsets: &[f32],
    taps: &[f32],
    bias: Option<&[f32]>,
    oy: usize,
) -> Vec<f32> {
    let mut row = vec![0f32; O * g.out_w];
    for ox in 0..g.out_w {
        let mut partial = [[0f32; C]; O];
        for_each_tap(g, offsets, oy, ox, |k, corners| {
            let mut sample = [0f32; C];
            corners.sample(image, &mut sample);
            let weights = &taps[k * O * C..][..O * C];
            for (oc, sums) in partial.iter_mut().enumerate() {
                for j in 0..C {
                    sums[j] += weights[oc * C + j] * sample[j];
                }
            }
        });
        for (oc, sums) in partial.iter().enumerate() {
            row[oc * g.out_w + ox] = bias.map_or(0.0, |b| b[oc]) + sums.iter().sum::<f32>();
        }
    }
    row
}

/// Calls `visit(k, corners)` for every kernel tap `k` of output pixel `(oy, ox)` whose sampling
/// position (the tap's place moved by its offset) is less than a pixel outside the input; the
/// other taps sample zero.
#[inline(always)]
pub(crate) fn for_each_tap(g: Geometry, offsets: &[f32], oy: usize, ox: usize, mut visit: impl FnMut(usize, &Corners)) {
    let (plane_out, at) = (g.out_h * g.out_w, oy * g.out_w + ox);
    for k in 0..g.kh * g.kw {
        let (ki, kj) = (k / g.kw, k % g.kw);
        let dy = offsets[2 * k * plane_out + at];
        let dx = offsets[(2 * k + 1) * plane_out + at];
        let y = (oy * g.stride[0] + ki * g.dilation[0]) as f32 - g.padding[0] as f32 + dy;
        let x = (ox * g.stride[1] + kj * g.dilation[1]) as f32 - g.padding[1] as f32 + dx;
        if let Some(corners) = Corners::new(y, x, g.h, g.w) {
            visit(k, &corners);
        }
    }
}

/// The four neighbours of a sampling position and their bilinear weights, a neighbour outside
/// the input with weight zero; with the position's fractional parts and which neighbours lie in
/// the input, which the backward's slopes need.
pub(crate) struct Corners {
    pub(crate) index: [usize; 4],
    pub(crate) weight: [f32; 4],
    /// Whether each neighbour lies in the input (one outside reads zero, takes no gradient).
    pub(crate) valid: [bool; 4],
    /// The fractional parts of the position: row `ly`, column `lx`.
    pub(crate) ly: f32,
    pub(crate) lx: f32,
}

impl Corners {
    /// `None` where the position lies a whole pixel or more outside the input (the sample is 0).
    #[inline(always)]
    fn new(y: f32, x: f32, h: usize, w: usize) -> Option<Self> {
        if y <= -1.0 || y >= h as f32 || x <= -1.0 || x >= w as f32 {
            return None;
        }
        // `floor` on (-1, size): a call into libm on the baseline x86-64 target, so by hand.
        let floor = |v: f32| if v < 0.0 { -1 } else { v as isize };
        let (y0, x0) = (floor(y), floor(x));
        let (ly, lx) = (y - y0 as f32, x - x0 as f32);
        let (hy, hx) = (1.0 - ly, 1.0 - lx);
        let mut index = [0; 4];
        let mut weight = [hy * hx, hy * lx, ly * hx, ly * lx];
        let mut valid = [false; 4];
        for (i, (dy, dx)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
            let (yy, xx) = (y0 + dy, x0 + dx);
            if yy >= 0 && (yy as usize) < h && xx >= 0 && (xx as usize) < w {
                index[i] = yy as usize * w + xx as usize;
                valid[i] = true;
            } else {
                weight[i] = 0.0;
            }
        }
        Some(Self { index, weight, valid, ly, lx })
    }

    /// The bilinear samples of all channels of `image` (`[H·W][C]`) into `out` (`C` long), each
    /// summed in burn's order.
    #[inline(always)]
    pub(crate) fn sample(&self, image: &[f32], out: &mut [f32]) {
        let c = out.len();
        let (i, k) = (&self.index, &self.weight);
        let [a, b, cc, d] =
            [&image[i[0] * c..][..c], &image[i[1] * c..][..c], &image[i[2] * c..][..c], &image[i[3] * c..][..c]];
        for j in 0..c {
            out[j] = k[0] * a[j] + k[1] * b[j] + k[2] * cc[j] + k[3] * d[j];
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::nn::conv::DeformConv2dConfig;
    use burn::tensor::module::deform_conv2d;
    use burn::tensor::ops::DeformConvOptions;
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::max_abs_diff;

    use super::*;

    /// The host kernel against burn's `deform_conv2d` (the reference) on DGIA's shape and on
    /// strided, dilated, unpadded and non-square cases, with offsets large enough to send samples
    /// past every border; fails on an error above 1e-5 of the output's magnitude. `geometry` is
    /// `[stride, dilation, padding]`.
    fn case(n: usize, [c, o]: [usize; 2], [h, w]: [usize; 2], [kh, kw]: [usize; 2], geometry: [usize; 3], bias: bool) {
        let [stride, dilation, pad] = geometry;
        let device = Device::flex();
        let conv = DeformConv2dConfig::new([c, o], [kh, kw])
            .with_stride([stride, stride])
            .with_dilation([dilation, dilation])
            .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
            .with_bias(bias)
            .init(&device);
        let conv =
            DeformConv2d { bias: conv.bias.map(|b| b.map(|t| t.random_like(Distribution::Normal(0.0, 1.0)))), ..conv };
        let out_h = (h + 2 * pad - dilation * (kh - 1) - 1) / stride + 1;
        let out_w = (w + 2 * pad - dilation * (kw - 1) - 1) / stride + 1;
        let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let offset = Tensor::<4>::random([n, 2 * kh * kw, out_h, out_w], Distribution::Uniform(-3.0, 3.0), &device);
        let options = DeformConvOptions::new([stride; 2], [pad; 2], [dilation; 2], 1, 1);
        let bias_value = conv.bias.as_ref().map(|b| b.val());
        let reference = deform_conv2d(x.clone(), offset.clone(), conv.weight.val(), None, bias_value, options);
        let got = deform_conv2d_host(&conv, x, offset).expect("one weight and offset group");
        assert_eq!(got.dims(), reference.dims());
        let scale = host_values(reference.clone()).iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        let worst = max_abs_diff(got, reference);
        assert!(
            worst <= 1e-5 * scale,
            "n {n} c {c} o {o} {h}x{w} k {kh}x{kw} s {stride} d {dilation} p {pad}: {worst} of {scale}"
        );
    }

    #[test]
    fn host_deformable_convolution_agrees_with_burn() {
        case(2, [16, 3], [11, 13], [3, 3], [1, 1, 1], true); // DGIA's shape
        case(1, [8, 3], [7, 9], [3, 3], [1, 1, 1], true); // the other specialised channel count
        case(1, [16, 4], [6, 5], [3, 3], [1, 1, 1], false); // 16 channels in, not 3 out: generic
        case(1, [5, 4], [9, 7], [3, 3], [2, 1, 1], false);
        case(1, [3, 2], [10, 12], [3, 3], [1, 2, 2], true);
        case(1, [4, 3], [8, 9], [2, 3], [1, 1, 0], true);
        case(1, [2, 5], [1, 1], [1, 1], [1, 1, 0], true);
    }

    #[test]
    fn several_groups_fall_back_to_burn() {
        let device = Device::flex();
        let conv = DeformConv2dConfig::new([4, 4], [3, 3]).with_weight_groups(2).init(&device);
        let x = Tensor::<4>::zeros([1, 4, 5, 5], &device);
        let offset = Tensor::<4>::zeros([1, 18, 3, 3], &device);
        assert!(deform_conv2d_host(&conv, x, offset).is_none());
    }
}
