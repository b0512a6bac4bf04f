//! The ConvGRU step for CPU inference with its element-wise work fused into two parallel passes.
//!
//! Design decision: burn's CPU backend runs each element-wise operation as its own pass on one
//! thread, and a GRU step has a dozen of them between its two convolutions (concatenations, the
//! context additions, sigmoid, the reset product, tanh, the blend). Here the step stays on host
//! buffers from the concatenated input to the new state: the fused-gate convolution and the
//! candidate convolution run the workspace's host convolution on those buffers, pass one computes
//! both gates and writes `[r·h, x]` straight into the candidate's input, pass two computes the
//! candidate's `tanh` and the blend, both in parallel over channel planes. Where both
//! convolutions take the Winograd path (the GRUs' sizes), the candidate's `x` channels are not
//! transformed a second time: the gates' convolution keeps the candidate's products over them
//! (`conv2d_host_shared_first`) and pass one writes `r·h` alone. Used only where the
//! host kernels apply (CPU inference, the dispatch's host path, `crate::ops::gru`); the tensor-op
//! step there stays the reference and its tests check both agree.

use burn::nn::conv::Conv2d;
use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::{host_values, planes_from, zeros_parallel};
use rayon::prelude::*;

use super::conv::PendingConv;
use super::conv::{conv2d_host_shared_first, conv2d_host_shared_second, conv2d_host_slices};
use crate::algorithm::{ConvAlgorithm, GruAlgorithm};
use crate::geometry::{Epilogue, conv_options};

/// `tanh` as a rational function (odd degree-13 numerator, even degree-6 denominator, the
/// minimax fit Eigen uses for `float`), clamped where `tanh` is ±1 in `f32`. Branch-free, so the
/// passes below vectorise; libm's scalar `tanhf`/`expf` were ~7 % of CPU inference. Largest
/// error against `f32::tanh` on a dense grid: 4.2e-7, a few units in the last place (tested).
#[inline(always)]
fn tanh_fast(x: f32) -> f32 {
    const CLAMP: f32 = 7.905_311;
    const A: [f32; 7] =
        [4.893_524_6e-3, 6.372_619_3e-4, 1.485_722_4e-5, 5.122_297e-8, -8.604_672e-11, 2.000_188e-13, -2.760_768_5e-16];
    const B: [f32; 4] = [4.893_525e-3, 2.268_434_6e-3, 1.185_347_1e-4, 1.198_258_4e-6];
    let x = x.clamp(-CLAMP, CLAMP);
    let x2 = x * x;
    // Horner's scheme in x², highest coefficient first.
    let polynomial = |coefficients: &[f32]| coefficients.iter().rev().fold(0.0, |acc, &k| acc * x2 + k);
    x * polynomial(&A) / polynomial(&B)
}

/// `σ(v) = (1 + tanh(v / 2)) / 2`, exactly the logistic function, through [`tanh_fast`].
#[inline(always)]
fn sigmoid(v: f32) -> f32 {
    0.5 + 0.5 * tanh_fast(0.5 * v)
}

/// One step `h' = (1 - z)·h + z·tanh(convq([r·h, x]) + cq)` on the host, `x` being the
/// concatenation of `inputs` (never built: their planes go straight into `[h, x]`), with
/// `z = σ(convz([h, x]) + cz)`, `r = σ(convr([h, x]) + cr)`; `zr_ctx` is `[cz, cr]` stacked
/// along channels, `q_ctx` is `cq`.
///
/// # Shapes
/// - `h`, `q_ctx`: `[N, C, H, W]`; `zr_ctx`: `[N, 2·C, H, W]`; `inputs[i]`: `[N, C_i, H, W]`;
///   output `[N, C, H, W]`
///
/// The convolutions run by `algorithm`, the dispatch's choice for the step. `None` (nothing
/// computed) when a convolution has options the host kernel does not take (the dispatch gives
/// such a step no host algorithm).
pub(crate) fn step(
    [convz, convr, convq]: [&Conv2d; 3],
    h: Tensor<4>,
    [zr_ctx, q_ctx]: [&Tensor<4>; 2],
    inputs: &[Tensor<4>],
    algorithm: GruAlgorithm,
) -> Option<Tensor<4>> {
    let (zr_options, q_options) = (conv_options(convz)?, conv_options(convq)?);
    let device = h.device();
    let [n, c, hh, ww] = h.dims();
    let plane = hh * ww;
    // Each input's values and channel count; x's channel `j` is channel `j - (channels before)`
    // of the input that holds it.
    let parts: Vec<_> = inputs.iter().map(|t| (host_values(t.clone()), t.dims()[1])).collect();
    let cx: usize = parts.iter().map(|(_, channels)| channels).sum();
    let channels = c + cx;
    let hv = host_values(h);
    let input_plane = |b: usize, mut j: usize| {
        for (values, count) in &parts {
            if j < *count {
                return &values[(b * count + j) * plane..][..plane];
            }
            j -= count;
        }
        unreachable!("channel {j} past the inputs' {cx}")
    };

    // [h, x] per image, the gates' input; later reused as [r·h, x], the candidate's input.
    let mut hx = zeros_parallel(n * channels * plane);
    hx.par_chunks_mut(plane).enumerate().for_each(|(i, dst)| {
        let (b, ch) = (i / channels, i % channels);
        let src = if ch < c { &hv[(b * c + ch) * plane..][..plane] } else { input_plane(b, ch - c) };
        dst.copy_from_slice(src);
    });

    let zr_weight = Tensor::cat(vec![convz.weight.val(), convr.weight.val()], 0);
    let zr_bias = match (&convz.bias, &convr.bias) {
        (Some(bz), Some(br)) => Some(Tensor::cat(vec![bz.val(), br.val()], 0)),
        _ => None,
    };
    let (zr_weight, zr_bias) = (host_values(zr_weight), zr_bias.map(host_values));
    let [_, _, kh, kw] = convz.weight.dims();
    let [_, _, qh, qw] = convq.weight.dims();
    let q_weight = host_values(convq.weight.val());
    let q_bias = convq.bias.as_ref().map(|b| host_values(b.val()));
    let dims = [n, channels, hh, ww];
    // With Winograd (the GRUs' sizes) the candidate's x channels are transformed once, by the
    // gates' convolution, which keeps the candidate's products over them.
    let (gates, candidate) = match algorithm {
        GruAlgorithm::Shared(tile) | GruAlgorithm::SharedBf16(tile, _) => {
            let unit = match algorithm {
                GruAlgorithm::SharedBf16(_, unit) => Some(unit),
                _ => None,
            };
            let weights = [&zr_weight[..], &q_weight[..]];
            let zr_bias = zr_bias.as_deref();
            let (gates, pending) = conv2d_host_shared_first(
                &hx,
                dims,
                weights,
                [2 * c, c],
                channels,
                cx,
                zr_bias,
                &zr_options,
                tile,
                unit,
            );
            (gates, Candidate::Pending(Box::new(pending)))
        }
        GruAlgorithm::Separate { gates, candidate } => {
            let zr_dims = [2 * c, channels, kh, kw];
            let zr_bias = zr_bias.as_deref();
            let linear = Epilogue::Linear;
            let (gates, _) = conv2d_host_slices(&hx, dims, &zr_weight, zr_dims, zr_bias, &zr_options, gates, linear);
            (gates, Candidate::Own(candidate))
        }
    };
    let zr_ctx = host_values(zr_ctx.clone());

    // Pass one: z (kept) and r·h: into its own buffer where the candidate's x channels are
    // pending, else over h's planes of `hx` (the x planes stay).
    let z = planes_from(n * c, plane, |i| {
        let (b, ch) = (i / c, i % c);
        let g = &gates[(b * 2 * c + ch) * plane..][..plane];
        let k = &zr_ctx[(b * 2 * c + ch) * plane..][..plane];
        g.iter().zip(k).map(|(g, k)| sigmoid(g + k))
    });
    // The reset gate's pre-activation and context of h's channel plane `i` (image-major).
    let reset = |i: usize| {
        let at = ((i / c) * 2 * c + c + i % c) * plane;
        (&gates[at..][..plane], &zr_ctx[at..][..plane])
    };
    let q = match candidate {
        Candidate::Pending(pending) => {
            let rh = planes_from(n * c, plane, |i| {
                let ((g, k), h) = (reset(i), &hv[i * plane..][..plane]);
                h.iter().zip(g).zip(k).map(|((h, g), k)| h * sigmoid(g + k))
            });
            conv2d_host_shared_second(*pending, &rh, [n, c, hh, ww], q_bias.as_deref()).0
        }
        Candidate::Own(algorithm) => {
            hx.par_chunks_mut(plane).enumerate().filter(|(i, _)| i % channels < c).for_each(|(i, dst)| {
                let (g, k) = reset((i / channels) * c + i % channels);
                for ((d, g), k) in dst.iter_mut().zip(g).zip(k) {
                    *d *= sigmoid(g + k);
                }
            });
            let q_dims = [c, channels, qh, qw];
            conv2d_host_slices(&hx, dims, &q_weight, q_dims, q_bias.as_deref(), &q_options, algorithm, Epilogue::Linear)
                .0
        }
    };
    let q_ctx = host_values(q_ctx.clone());

    // Pass two: the new state.
    let out = planes_from(n * c, plane, |i| {
        let s = i * plane;
        let (z, h, q, k) = (&z[s..s + plane], &hv[s..s + plane], &q[s..s + plane], &q_ctx[s..s + plane]);
        z.iter().zip(h).zip(q).zip(k).map(|(((z, h), q), k)| (1.0 - z) * h + z * tanh_fast(q + k))
    });
    Some(Tensor::from_data(TensorData::new(out, [n, c, hh, ww]), &device))
}

/// The candidate's convolution: its products over the shared `x` channels already taken, or its
/// own algorithm over the whole `[r·h, x]`.
enum Candidate {
    Pending(Box<PendingConv>),
    Own(ConvAlgorithm),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rational `tanh` and the logistic function through it stay within a few units in the
    /// last place of libm's, over the range where they change and far outside it.
    #[test]
    fn fast_activations_match_libm() {
        let (mut worst_tanh, mut worst_sigmoid) = (0f32, 0f32);
        for i in -400_000..=400_000 {
            let x = i as f32 * 5e-5;
            worst_tanh = worst_tanh.max((tanh_fast(x) - x.tanh()).abs());
            worst_sigmoid = worst_sigmoid.max((sigmoid(x) - 1.0 / (1.0 + (-x).exp())).abs());
        }
        for x in [-1e30f32, -100.0, -9.0, 9.0, 100.0, 1e30] {
            assert_eq!(tanh_fast(x), x.signum(), "{x}");
        }
        assert_eq!(tanh_fast(0.0), 0.0);
        assert!(tanh_fast(1e-6) > 0.0 && (tanh_fast(1e-6) - 1e-6).abs() < 1e-12);
        assert!(worst_tanh < 5e-7, "tanh: {worst_tanh}");
        assert!(worst_sigmoid < 5e-7, "sigmoid: {worst_sigmoid}");
    }
}
