//! The gradients of DGIA's deformable convolution on host buffers, for training on the CPU.
//!
//! Design decision: burn Flex's backward of `deform_conv2d` runs on one thread per image and
//! took about a sixth of a training step of the paper's model. Here every output pixel walks its
//! kernel taps with the forward's own walk and corners (`crate::host::deform`): per tap the bilinear sample of all
//! channels gives the weight's gradient, the sample's gradient (the output gradient through the
//! tap's weights) is scattered to the four corners and gives the offset's gradient through the
//! bilinear weights' derivatives. The scatter writes anywhere in the image (the offsets are
//! free), so each of a fixed number of row groups sums into its own buffer and the buffers are
//! added in order: the same sums on any thread count.

use rayon::prelude::*;

use super::deform::{Corners, Geometry, channels_innermost, for_each_tap, weight_per_tap};

/// Row groups of one image whose input and weight gradients are summed apart, then in order.
const GROUPS: usize = 4;

/// The gradients of a deformable convolution: input `[N, C, H, W]`, offset `[N, 2·kh·kw, H_out,
/// W_out]`, weight `[O, C, kh, kw]`, bias `[O]`.
pub struct DeformGradients {
    /// The input's gradient.
    pub input: Vec<f32>,
    /// The offsets' gradient.
    pub offset: Vec<f32>,
    /// The weight's gradient.
    pub weight: Vec<f32>,
    /// The bias's gradient.
    pub bias: Vec<f32>,
}

/// One group's sums: the input's gradient (one image, channels innermost), the weight's (`[k][O][C]`)
/// and the bias's.
struct Partial {
    input: Vec<f32>,
    weight: Vec<f32>,
    bias: Vec<f64>,
}

/// The gradients of `deform_slices(x, n, offset, weight, bias, g)` given the output gradient
/// `grad` (`[N, O, H_out, W_out]`).
pub(crate) fn deform_backward(
    x: &[f32],
    n: usize,
    offset: &[f32],
    weight: &[f32],
    grad: &[f32],
    g: Geometry,
) -> DeformGradients {
    let (c, o, taps_n, out_h, out_w) = (g.c, g.o, g.kh * g.kw, g.out_h, g.out_w);
    let (plane_in, plane) = (g.h * g.w, out_h * out_w);
    let pixels = channels_innermost(x, n, g);
    let taps = weight_per_tap(weight, g);
    let mut d_offset = vec![0f32; n * 2 * taps_n * plane];
    let mut d_input = vec![0f32; n * c * plane_in];
    let mut d_taps = vec![0f32; taps_n * o * c];
    let mut d_bias = vec![0f64; o];
    for b in 0..n {
        let image = &pixels[b * plane_in * c..][..plane_in * c];
        let offsets = &offset[b * 2 * taps_n * plane..][..2 * taps_n * plane];
        let g_image = &grad[b * o * plane..][..o * plane];
        let groups = GROUPS.min(out_h.max(1));
        let group_rows = |group: usize| group * out_h / groups..(group + 1) * out_h / groups;
        // Each group owns its rows of the offsets' gradient, written once per pixel.
        let partials: Vec<(Partial, Vec<f32>)> = (0..groups)
            .into_par_iter()
            .map(|group| {
                let rows = group_rows(group);
                let per_channel = rows.len() * out_w;
                let mut partial = Partial {
                    input: vec![0f32; plane_in * c],
                    weight: vec![0f32; taps_n * o * c],
                    bias: vec![0f64; o],
                };
                let mut d_off = vec![0f32; 2 * taps_n * per_channel];
                let (mut sample, mut d_sample, mut dy, mut dx) =
                    (vec![0f32; c], vec![0f32; c], vec![0f32; c], vec![0f32; c]);
                let mut g_pixel = vec![0f32; o];
                for oy in rows.clone() {
                    for ox in 0..out_w {
                        let at = oy * out_w + ox;
                        for (oc, v) in g_pixel.iter_mut().enumerate() {
                            *v = g_image[oc * plane + at];
                            partial.bias[oc] += f64::from(*v);
                        }
                        let local = (oy - rows.start) * out_w + ox;
                        for_each_tap(g, offsets, oy, ox, |k, corners| {
                            corners.sample(image, &mut sample);
                            slopes(corners, image, &mut dy, &mut dx);
                            let w_tap = &taps[k * o * c..][..o * c];
                            let dw_tap = &mut partial.weight[k * o * c..][..o * c];
                            d_sample.fill(0.0);
                            for oc in 0..o {
                                let go = g_pixel[oc];
                                let (w_row, dw_row) = (&w_tap[oc * c..][..c], &mut dw_tap[oc * c..][..c]);
                                for j in 0..c {
                                    dw_row[j] += go * sample[j];
                                    d_sample[j] += go * w_row[j];
                                }
                            }
                            scatter(corners, &mut partial.input, &d_sample);
                            d_off[2 * k * per_channel + local] = d_sample.iter().zip(&dy).map(|(a, b)| a * b).sum();
                            d_off[(2 * k + 1) * per_channel + local] =
                                d_sample.iter().zip(&dx).map(|(a, b)| a * b).sum();
                        });
                    }
                }
                (partial, d_off)
            })
            .collect();
        for (group, (partial, d_off)) in partials.into_iter().enumerate() {
            let rows = group_rows(group);
            let per_channel = rows.len() * out_w;
            for ch in 0..2 * taps_n {
                d_offset[(b * 2 * taps_n + ch) * plane + rows.start * out_w..][..per_channel]
                    .copy_from_slice(&d_off[ch * per_channel..][..per_channel]);
            }
            d_taps.iter_mut().zip(&partial.weight).for_each(|(t, v)| *t += v);
            d_bias.iter_mut().zip(&partial.bias).for_each(|(t, v)| *t += v);
            // The input's gradient back to `[C, H, W]`, the groups added in order.
            let d_image = &mut d_input[b * c * plane_in..][..c * plane_in];
            d_image.par_chunks_mut(plane_in).enumerate().for_each(|(ic, channel)| {
                for (p, v) in channel.iter_mut().enumerate() {
                    *v += partial.input[p * c + ic];
                }
            });
        }
    }
    // The weight's gradient from `[k][O][C]` back to `[O, C, kh, kw]`.
    let mut d_weight = vec![0f32; o * c * taps_n];
    for k in 0..taps_n {
        for oc in 0..o {
            for ic in 0..c {
                d_weight[(oc * c + ic) * taps_n + k] = d_taps[(k * o + oc) * c + ic];
            }
        }
    }
    DeformGradients {
        input: d_input,
        offset: d_offset,
        weight: d_weight,
        bias: d_bias.iter().map(|&v| v as f32).collect(),
    }
}

/// The derivatives of the bilinear sample of every channel of `image` (`[H·W][C]`) along the
/// row (`dy`) and the column (`dx`) of the position, a neighbour outside the input reading zero.
fn slopes(corners: &Corners, image: &[f32], dy: &mut [f32], dx: &mut [f32]) {
    let c = dy.len();
    let at = |i: usize| if corners.valid[i] { &image[corners.index[i] * c..][..c] } else { &image[..0] };
    let corner = [at(0), at(1), at(2), at(3)];
    let (ly, lx) = (corners.ly, corners.lx);
    let (hy, hx) = (1.0 - ly, 1.0 - lx);
    for j in 0..c {
        let v: [f32; 4] = std::array::from_fn(|i| corner[i].get(j).copied().unwrap_or(0.0));
        dy[j] = hx * (v[2] - v[0]) + lx * (v[3] - v[1]);
        dx[j] = hy * (v[1] - v[0]) + ly * (v[3] - v[2]);
    }
}

/// Adds `d_sample` (one value per channel) times each corner's weight to the corners of
/// `d_image` (`[H·W][C]`) that lie in the input.
fn scatter(corners: &Corners, d_image: &mut [f32], d_sample: &[f32]) {
    let c = d_sample.len();
    for i in 0..4 {
        if corners.valid[i] {
            let dst = &mut d_image[corners.index[i] * c..][..c];
            for j in 0..c {
                dst[j] += corners.weight[i] * d_sample[j];
            }
        }
    }
}
