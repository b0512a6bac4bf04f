//! The host convolution's path for stride-1 convolutions with few output channels: one product
//! per band of rows over the unshifted input, then shifted sums.
//!
//! Design decision: the im2col path builds a `C·kh·kw x P` column matrix for every tile of
//! output pixels; with many input channels and few outputs (the flow head's last convolution,
//! 256 -> 2 channels, every update iteration) building it is nearly all of the work, since the
//! product that follows has only `O` rows. Here the product is taken first over the input as it
//! lies (`Z = W' X` with `W'` the `O·kh·kw x C` weight and `X` the band's input rows, read in place
//! as a strided operand: no copy), and the output is the sum of `kh·kw` shifted planes of `Z`, so
//! the input is read once instead of `kh·kw` times and nothing of its size is written.
//!
//! The products go through [`crate::product::matmul_strided`]. The dispatch decides which
//! convolutions take this path (few outputs from many input channels).

use rayon::prelude::*;

use crate::geometry::{Epilogue, band_jobs};
use crate::product::matmul_strided;

/// Output rows per band: enough pixels for the product, bands enough for both cores.
const BAND_PIXELS: usize = 1024;

/// A stride-1 convolution with few outputs; returns the output and its dimensions.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `wt`: `[O, C, kh, kw]`; `bias`: `[O]`
/// - `padding` `[(top, bottom), (left, right)]`, `dilation` `[dh, dw]`; output `[N, O, H_out, W_out]`
///   with `H_out = H + top + bottom - dh·(kh - 1)` (likewise `W_out`), which must be positive
#[allow(clippy::too_many_arguments)]
pub(crate) fn few_outputs_conv(
    x: &[f32],
    x_dims: [usize; 4],
    wt: &[f32],
    [o, _, kh, kw]: [usize; 4],
    bias: Option<&[f32]>,
    padding: [(usize, usize); 2],
    [dh, dw]: [usize; 2],
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    let [n, c, h, w] = x_dims;
    let [(ph, ph_end), (pw, pw_end)] = padding;
    let (out_h, out_w) = (h + ph + ph_end - dh * (kh - 1), w + pw + pw_end - dw * (kw - 1));
    let taps = kh * kw;
    // W'[(o, ky, kx)][c]: the rows of the product, one per output channel and tap.
    let mut lhs = vec![0.0f32; o * taps * c];
    for oc in 0..o {
        for ci in 0..c {
            for tap in 0..taps {
                lhs[(oc * taps + tap) * c + ci] = wt[(oc * c + ci) * taps + tap];
            }
        }
    }
    let band_rows = (BAND_PIXELS / out_w.max(1)).clamp(1, out_h);
    let bands = out_h.div_ceil(band_rows);
    let plane = out_h * out_w;
    let mut out = vec![0.0f32; n * o * plane];
    // One job per (image, band): its rows of every output plane.
    band_jobs(&mut out, o, plane, band_rows * out_w).into_par_iter().enumerate().for_each(|(job, planes)| {
        let (b, band) = (job / bands, job % bands);
        let oy0 = band * band_rows;
        let rows = band_rows.min(out_h - oy0);
        // Input rows the band reaches, clipped to the input: oy - ph + ky·dh.
        let iy0 = oy0.saturating_sub(ph).min(h);
        let iy1 = (oy0 + rows - 1 + dh * (kh - 1) + 1).saturating_sub(ph).min(h);
        let mut z = vec![0.0f32; o * taps * (iy1 - iy0) * w];
        if iy1 > iy0 {
            let image = &x[b * c * h * w..][..c * h * w];
            let cols = (iy1 - iy0) * w;
            // The last channel's operand ends at the band's last row, not at the plane's end.
            matmul_strided(&mut z, cols, &lhs, c, &image[iy0 * w..], h * w, [o * taps, cols, c]);
        }
        for (oc, dst) in planes.into_iter().enumerate() {
            let add = bias.map_or(0.0, |v| v[oc]);
            dst.fill(add);
            for tap in 0..taps {
                let (ky, kx) = (tap / kw, tap % kw);
                let zt = &z[(oc * taps + tap) * (iy1 - iy0) * w..][..(iy1 - iy0) * w];
                // Output column ox reads input column ox + kx·dw - pw.
                let shift = (kx * dw) as isize - pw as isize;
                let lo = (-shift).clamp(0, out_w as isize) as usize;
                let hi = (w as isize - shift).clamp(lo as isize, out_w as isize) as usize;
                for r in 0..rows {
                    let Some(iy) = (oy0 + r + ky * dh).checked_sub(ph).filter(|&iy| iy < h) else { continue };
                    let src = &zt[(iy - iy0) * w..][..w];
                    let row = &mut dst[r * out_w..][..out_w];
                    let start = (lo as isize + shift) as usize;
                    for (d, s) in row[lo..hi].iter_mut().zip(&src[start..]) {
                        *d += s;
                    }
                }
            }
            if epilogue == Epilogue::Relu {
                dst.iter_mut().for_each(|v| *v = v.max(0.0));
            }
        }
    });
    (out, [n, o, out_h, out_w])
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::ops::ConvOptions;
    use burn::tensor::{Device, Distribution, Tensor};

    use super::*;
    use dgstereo_core::tensor::to_vec;

    /// Against burn's convolution (the reference), with and without bias and ReLU.
    fn case(
        n: usize,
        [c, o]: [usize; 2],
        [h, w]: [usize; 2],
        [kh, kw]: [usize; 2],
        padding: [(usize, usize); 2],
        dil: usize,
    ) {
        let device = Device::flex();
        let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let wt = Tensor::<4>::random([o, c, kh, kw], Distribution::Normal(0.0, 0.1), &device);
        let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
        let options = ConvOptions::new_with_padding([1, 1], padding, [dil, dil], 1);
        let (xv, wv, bv) = (to_vec(x.clone()), to_vec(wt.clone()), to_vec(b.clone()));
        for bias in [true, false] {
            let reference = conv2d(x.clone(), wt.clone(), bias.then(|| b.clone()), options.clone());
            let dims = reference.dims();
            let expected = to_vec(reference);
            let scale = expected.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
            for epilogue in [Epilogue::Linear, Epilogue::Relu] {
                let bias_values = bias.then_some(&bv[..]);
                let (got, got_dims) = few_outputs_conv(
                    &xv,
                    [n, c, h, w],
                    &wv,
                    [o, c, kh, kw],
                    bias_values,
                    padding,
                    [dil, dil],
                    epilogue,
                );
                let shape =
                    format!("n {n} c {c} o {o} {h}x{w} k {kh}x{kw} {padding:?} dil {dil} bias {bias} {epilogue:?}");
                assert_eq!(got_dims, dims, "{shape}");
                for (g, e) in got.iter().zip(&expected) {
                    let e = if epilogue == Epilogue::Relu { e.max(0.0) } else { *e };
                    assert!((g - e).abs() <= 1e-5 * scale, "{shape}: {g} against {e}");
                }
            }
        }
    }

    #[test]
    fn few_outputs_agree_with_burn() {
        let same = [(1, 1), (1, 1)];
        case(1, [64, 2], [12, 14], [3, 3], same, 1); // the flow head's shape, small
        case(2, [32, 1], [7, 9], [3, 3], same, 1);
        case(1, [40, 4], [1, 5], [3, 3], same, 1); // one row
        case(1, [33, 3], [6, 1], [3, 3], same, 1); // one column
        case(1, [32, 2], [5, 6], [3, 3], [(0, 0), (0, 0)], 1); // no padding
        case(1, [32, 2], [9, 8], [3, 3], [(2, 0), (1, 3)], 1); // asymmetric
        case(1, [32, 3], [11, 10], [3, 3], [(2, 2), (2, 2)], 2); // dilated
        case(1, [48, 2], [9, 11], [5, 3], [(2, 2), (1, 1)], 1); // not square
        case(1, [32, 4], [6, 7], [1, 1], [(0, 0), (0, 0)], 1); // 1x1
        // Several bands per image (BAND_PIXELS / width rows each), a last band shorter.
        case(1, [32, 2], [37, 100], [3, 3], same, 1);
        case(1, [32, 2], [5, 1500], [3, 3], same, 1); // one row per band
    }
}
