//! The deformable convolution: the host kernel for CPU inference (`crate::host::deform`) and a
//! node with our backward in training (`crate::autodiff::deform`) where the convolution suits
//! them, burn's `DeformConv2d` (the reference) everywhere else.

use burn::nn::conv::DeformConv2d;
use burn::tensor::Tensor;

use crate::autodiff::deform::{DeformOptions, deform_conv2d};
use crate::dispatch::{DeformCall, Plan, plan};
use crate::host::deform::{Geometry, deform_conv2d_host};

/// `conv.forward(input, offset, None)`: without a modulation mask.
///
/// # Shapes
/// - `input`: `[N, C, H, W]`; `offset`: `[N, 2·kh·kw, H_out, W_out]`; output `[N, O, H_out, W_out]`
pub fn deform_conv2d_forward(conv: &DeformConv2d, input: Tensor<4>, offset: Tensor<4>) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::deform_macs(conv, offset.dims()));
    let options = DeformOptions::of(conv);
    let host = options.filter(|&o| Geometry::new(input.dims(), conv.weight.dims(), o).is_some());
    let ours = match plan(&input.device(), &DeformCall { host, training: options }) {
        Plan::HostTraining(options) => {
            let bias = conv.bias.as_ref().map(|b| b.val());
            Some(deform_conv2d(input.clone(), offset.clone(), conv.weight.val(), bias, options))
        }
        Plan::HostInference(_) => deform_conv2d_host(conv, input.clone(), offset.clone()),
        Plan::Gpu(()) | Plan::Stock => None,
    };
    ours.unwrap_or_else(|| conv.forward(input, offset, None))
}

#[cfg(test)]
mod tests {
    use burn::nn::PaddingConfig2d;
    use burn::nn::conv::DeformConv2dConfig;
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::max_abs_diff;

    use super::*;

    crate::test_paths!(
        /// Every path computes burn's deformable convolution on DGIA's shape (16 channels in, 3
        /// out, 3x3), with offsets that send samples past the borders.
        fn every_path_computes_burns_deformable_convolution(pinned) {
            let device = Device::flex();
            let conv = DeformConv2dConfig::new([16, 3], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(&device);
            let x = Tensor::<4>::random([1, 16, 11, 13], Distribution::Normal(0.0, 1.0), &device);
            let offset = Tensor::<4>::random([1, 18, 11, 13], Distribution::Uniform(-3.0, 3.0), &device);
            let want = conv.forward(x.clone(), offset.clone(), None);
            let scale = want.clone().abs().max().into_scalar::<f32>().max(1.0);
            let diff = max_abs_diff(want, deform_conv2d_forward(&conv, x, offset)) / scale;
            assert!(diff < 1e-5, "{pinned:?}: {diff}");
        }
    );

    /// The training node's output and its gradients of the input, the offsets, the weight and
    /// the bias against burn's own autodiff of `deform_conv2d` (the loss `Σ out·r`, `r` random):
    /// DGIA's shape, a strided one with 5 channels and a dilated one without a bias, offsets up to
    /// 3 pixels (samples past every border).
    #[test]
    fn training_node_agrees_with_burns_autodiff() {
        use burn::tensor::module::deform_conv2d as burn_deform_conv2d;
        use burn::tensor::ops::DeformConvOptions;
        use dgstereo_core::tensor::to_vec;

        let ad = Device::flex().autodiff();
        // Batch, [C, O], size, [stride, dilation, padding], bias.
        let cases = [
            (2, [16, 3], [11, 13], [1, 1, 1], true),
            (1, [5, 4], [9, 8], [2, 1, 1], true),
            (1, [3, 2], [10, 12], [1, 2, 2], false),
        ];
        for (n, [c, o], [h, w], [stride, dilation, pad], with_bias) in cases {
            let out_h = (h + 2 * pad - dilation * 2 - 1) / stride + 1;
            let out_w = (w + 2 * pad - dilation * 2 - 1) / stride + 1;
            let rand = |dims: [usize; 4], d: Distribution| Tensor::<4>::random(dims, d, &ad);
            let x = rand([n, c, h, w], Distribution::Normal(0.0, 1.0));
            let offset = rand([n, 18, out_h, out_w], Distribution::Uniform(-3.0, 3.0));
            let weight = rand([o, c, 3, 3], Distribution::Normal(0.0, 0.3));
            let bias = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &ad);
            let r = rand([n, o, out_h, out_w], Distribution::Normal(0.0, 1.0));
            let run = |ours: bool| {
                let [x, offset, weight] = [&x, &offset, &weight].map(|t| t.clone().detach().require_grad());
                let b = bias.clone().detach().require_grad();
                let bias = with_bias.then(|| b.clone());
                let y = if ours {
                    let options = DeformOptions { stride: [stride; 2], padding: [pad; 2], dilation: [dilation; 2] };
                    deform_conv2d(x.clone(), offset.clone(), weight.clone(), bias, options)
                } else {
                    let options = DeformConvOptions::new([stride; 2], [pad; 2], [dilation; 2], 1, 1);
                    burn_deform_conv2d(x.clone(), offset.clone(), weight.clone(), None, bias, options)
                };
                let grads = (y.clone() * r.clone()).sum().backward();
                let grad = |t: &Tensor<4>| to_vec(t.grad(&grads).expect("a gradient"));
                let gb = with_bias.then(|| b.grad(&grads).map(to_vec).expect("bias gradient"));
                (to_vec(y.detach()), grad(&x), grad(&offset), grad(&weight), gb)
            };
            let (want, got) = (run(false), run(true));
            let case = format!("n {n} c {c} o {o} {h}x{w} stride {stride} dilation {dilation} padding {pad}");
            let relative = |got: &[f32], want: &[f32]| {
                let scale = want.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
                got.iter().zip(want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale
            };
            assert!(relative(&got.0, &want.0) < 1e-5, "{case}: output");
            assert!(relative(&got.1, &want.1) < 1e-5, "{case}: input gradient");
            assert!(relative(&got.2, &want.2) < 1e-4, "{case}: offset gradient {}", relative(&got.2, &want.2));
            assert!(relative(&got.3, &want.3) < 1e-5, "{case}: weight gradient");
            if let (Some(a), Some(b)) = (&got.4, &want.4) {
                assert!(relative(a, b) < 1e-5, "{case}: bias gradient");
            }
        }
    }
}
