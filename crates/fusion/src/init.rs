//! Weight initialisation that makes a fusion module start as (nearly) the identity on the image.
//!
//! A freshly built fusion module must not scramble the image the pretrained encoders expect, so
//! both learned variants are initialised such that the enhanced image at step 0 is the input image
//! plus a small perturbation:
//!
//! 1. the image projection (1x1, `3 -> F`) copies the RGB channels into feature channels `0..3`
//!    (weight = identity, bias = 0); channels `3..F` keep burn's default initialisation;
//! 2. the depth projection (1x1, `1 -> F`) keeps burn's default initialisation;
//! 3. the offset conv of the deformable variant has zero weights and zero bias, so every sampling
//!    offset starts at 0 and the deformable conv starts as a plain 3x3 conv;
//! 4. the mixing conv (3x3, `2F -> 3`, deformable or plain) has its centre tap pick feature
//!    channel `o` back into output channel `o` (`weight[o, o, 1, 1] = 1`, `o < 3`), zero bias, and
//!    every other weight equal to burn's default (Kaiming-uniform) draw times
//!    [`MIXER_INIT_SCALE`].
//!
//! The output is then `image + sum(small weights * features)`, a few grey levels off the image.
//! Every parameter still learns from step 0: the zero offset conv's gradient is the deformable
//! conv's sensitivity to its sampling positions (non-zero through the identity taps) times `F_d`,
//! and the depth projection's gradient flows through the small mixing weights.

use burn::module::Param;
use burn::nn::conv::{Conv2d, DeformConv2d};
use burn::tensor::Tensor;
use dgstereo_core::tensor::{from_vec, to_vec};

/// Factor on the default initialisation of the mixing conv's weights other than the identity
/// taps. Small enough that the step-0 output is within a few grey levels of the input image.
pub const MIXER_INIT_SCALE: f32 = 1e-2;

/// The number of RGB channels.
pub(crate) const RGB: usize = 3;

/// Rewrites a 4-d parameter through `edit(values, shape)`.
fn edit_weight(param: &Param<Tensor<4>>, edit: impl FnOnce(&mut [f32], [usize; 4])) -> Param<Tensor<4>> {
    let value = param.val();
    let device = value.device();
    let shape = value.dims();
    let mut values = to_vec(value);
    edit(&mut values, shape);
    Param::from_tensor(from_vec(values, shape, &device))
}

/// Rewrites a 1-d parameter through `edit(values)`.
fn edit_bias(param: &Param<Tensor<1>>, edit: impl FnOnce(&mut [f32])) -> Param<Tensor<1>> {
    let value = param.val();
    let device = value.device();
    let shape = value.dims();
    let mut values = to_vec(value);
    edit(&mut values);
    Param::from_tensor(from_vec(values, shape, &device))
}

/// Flat index of `[a, b, c, d]` in a row-major tensor of `shape`.
fn index([a, b, c, d]: [usize; 4], shape: [usize; 4]) -> usize {
    ((a * shape[1] + b) * shape[2] + c) * shape[3] + d
}

/// Makes a 1x1 `3 -> F` conv copy the RGB channels into its first three outputs.
pub(crate) fn identity_padded_projection(mut conv: Conv2d) -> Conv2d {
    conv.weight = edit_weight(&conv.weight, |w, shape| {
        for o in 0..RGB {
            for i in 0..shape[1] {
                w[index([o, i, 0, 0], shape)] = if i == o { 1.0 } else { 0.0 };
            }
        }
    });
    conv.bias = conv.bias.as_ref().map(|b| edit_bias(b, |b| b[..RGB].fill(0.0)));
    conv
}

/// Zeroes a conv's weight and bias.
pub(crate) fn zeroed(mut conv: Conv2d) -> Conv2d {
    conv.weight = edit_weight(&conv.weight, |w, _| w.fill(0.0));
    conv.bias = conv.bias.as_ref().map(|b| edit_bias(b, |b| b.fill(0.0)));
    conv
}

/// The near-identity mixing weight: scaled default draw plus the centre-tap identity on the
/// first three input channels. Expects `[3, C_in, 3, 3]` with `C_in >= 3`.
fn near_identity_mixer_weight(param: &Param<Tensor<4>>) -> Param<Tensor<4>> {
    edit_weight(param, |w, shape| {
        w.iter_mut().for_each(|v| *v *= MIXER_INIT_SCALE);
        let (cy, cx) = (shape[2] / 2, shape[3] / 2);
        for o in 0..RGB {
            w[index([o, o, cy, cx], shape)] = 1.0;
        }
    })
}

/// Initialises a plain mixing conv near the identity on its first three input channels.
pub(crate) fn near_identity_conv(mut conv: Conv2d) -> Conv2d {
    conv.weight = near_identity_mixer_weight(&conv.weight);
    conv.bias = conv.bias.as_ref().map(|b| edit_bias(b, |b| b.fill(0.0)));
    conv
}

/// Initialises a deformable mixing conv near the identity on its first three input channels.
pub(crate) fn near_identity_deform_conv(mut conv: DeformConv2d) -> DeformConv2d {
    conv.weight = near_identity_mixer_weight(&conv.weight);
    conv.bias = conv.bias.as_ref().map(|b| edit_bias(b, |b| b.fill(0.0)));
    conv
}
