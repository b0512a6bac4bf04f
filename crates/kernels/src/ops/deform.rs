//! The deformable convolution: the host kernel for CPU inference ([`crate::host::deform`]) where
//! the convolution suits it, burn's `DeformConv2d` (the reference) everywhere else.

use burn::nn::conv::DeformConv2d;
use burn::tensor::Tensor;

use crate::dispatch::{Op, Path, path};
use crate::host::deform::deform_conv2d_host;

/// `conv.forward(input, offset, None)`: without a modulation mask.
///
/// # Shapes
/// - `input`: `[N, C, H, W]`; `offset`: `[N, 2·kh·kw, H_out, W_out]`; output `[N, O, H_out, W_out]`
pub fn deform_conv2d_forward(conv: &DeformConv2d, input: Tensor<4>, offset: Tensor<4>) -> Tensor<4> {
    let host = match path(&input.device(), Op::Deform) {
        Path::Host => deform_conv2d_host(conv, input.clone(), offset.clone()),
        Path::Gpu | Path::Stock => None,
    };
    host.unwrap_or_else(|| conv.forward(input, offset, None))
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
}
