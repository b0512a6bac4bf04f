//! How the encoders take a monocular network's features (DEFOM-Stereo's combined encoders).
//!
//! DEFOM-Stereo adds, after the residual trunk, a `ConvBlock` of the depth features to the
//! trunk's output at each level it reads: `x + relu(norm1(conv(d)))` (the feature encoder's
//! `convd` at 1/4, the context encoder's `conv08`, `conv16`, `conv32` at 1/4, 1/8, 1/16). The
//! images themselves are ImageNet-normalised there ([`InputNormalisation`]), as the monocular
//! network sees them.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::Numerics;
use serde::{Deserialize, Serialize};

use crate::norm::{Norm, NormKind};

/// Whether the encoders add a monocular network's features to their trunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum DepthFeatureInput {
    /// The image alone, normalised to -1..1 (RAFT-Stereo).
    #[default]
    None,
    /// The ImageNet-normalised image, with the monocular features added after the trunks by a
    /// [`DepthFeatureBlock`] per level (DEFOM-Stereo).
    Added,
}

impl DepthFeatureInput {
    /// Every kind, in the order of the enum.
    pub const ALL: [Self; 2] = [Self::None, Self::Added];

    /// The name the TOML key `depth_features` writes.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Added => "added",
        }
    }

    /// How the images are normalised before the encoders.
    pub fn normalisation(self) -> InputNormalisation {
        match self {
            Self::None => InputNormalisation::SignedUnit,
            Self::Added => InputNormalisation::ImageNet,
        }
    }
}

/// How images in 0..255 become the encoders' input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InputNormalisation {
    /// `x / 255 · 2 - 1` (RAFT-Stereo).
    #[default]
    SignedUnit,
    /// `(x - 255·mean) / (255·std)` with ImageNet's statistics, as DEFOM-Stereo's buffers hold
    /// them (each product rounded to float32, as `tensor([...]) * 255` is).
    ImageNet,
}

/// ImageNet channel means (RGB, 0..1).
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet channel standard deviations (RGB, 0..1).
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

impl InputNormalisation {
    /// Normalises images in 0..255.
    ///
    /// # Shapes
    /// - `x`: `[N, 3, H, W]` -> `[N, 3, H, W]`
    pub fn apply(self, x: Tensor<4>) -> Tensor<4> {
        match self {
            Self::SignedUnit => x.div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0),
            Self::ImageNet => {
                let device = x.device();
                let channels = |v: [f32; 3]| {
                    let scaled: Vec<f32> = v.iter().map(|c| c * 255.0).collect();
                    Tensor::<1>::from_data(TensorData::new(scaled, [3]), &device).reshape([1, 3, 1, 1])
                };
                (x - channels(IMAGENET_MEAN)) / channels(IMAGENET_STD)
            }
        }
    }
}

/// DEFOM-Stereo's `ConvBlock`: `relu(norm1(conv(x)))`, a 3x3 convolution to the trunk's width.
///
/// Its `norm2` (and `norm3`, where the widths differ) are built and stored as in the reference,
/// whose constructor copies `ResidualBlock`'s, but never applied.
///
/// # Shapes
/// - input `[N, C_in, H, W]`, output `[N, C_out, H, W]`
#[derive(Module, Debug)]
pub struct DepthFeatureBlock {
    /// 3x3 convolution.
    pub conv: Conv2d,
    /// The norm after it.
    pub norm1: Norm,
    /// Unused (stored by the reference).
    pub norm2: Norm,
    /// Unused (stored by the reference where the widths differ).
    pub norm3: Option<Norm>,
}

impl DepthFeatureBlock {
    /// A block from `in_channels` to `out_channels` with `norm`.
    pub fn new(in_channels: usize, out_channels: usize, norm: NormKind, device: &Device) -> Self {
        Self {
            conv: conv2d([in_channels, out_channels], 3, 1, 1, ConvInit::KaimingFanOut, device),
            norm1: norm.init(out_channels, device),
            norm2: norm.init(out_channels, device),
            norm3: (in_channels != out_channels).then(|| norm.init(out_channels, device)),
        }
    }

    /// `relu(norm1(conv(x)))`, with the rounding `numerics` allows in training.
    pub fn forward(&self, x: Tensor<4>, numerics: Numerics) -> Tensor<4> {
        self.norm1.conv_forward_relu(&self.conv, x, true, numerics)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::{from_vec, to_vec};

    /// `ALL` lists every kind serde accepts, once, in the enum's order, named as TOML writes it.
    #[test]
    fn every_kind_is_listed() {
        use serde::Deserialize;
        use serde::de::value::{Error, StrDeserializer};
        let accepted = dgstereo_core::serde_names::accepted_names::<DepthFeatureInput>().unwrap();
        let listed: Vec<&str> = DepthFeatureInput::ALL.iter().map(|k| k.name()).collect();
        assert_eq!(listed, accepted);
        for kind in DepthFeatureInput::ALL {
            assert_eq!(DepthFeatureInput::deserialize(StrDeserializer::<Error>::new(kind.name())), Ok(kind));
        }
    }

    /// The ImageNet normalisation is DEFOM-Stereo's `(x - mean·255) / (std·255)` in float32.
    #[test]
    fn imagenet_normalisation_is_the_references() {
        let device = default_device();
        let x = from_vec((0..12).map(|i| (i * 23) as f32).collect(), [1, 3, 2, 2], &device);
        let out = to_vec(InputNormalisation::ImageNet.apply(x));
        for (i, v) in out.iter().enumerate() {
            let c = i / 4;
            let expected = ((i * 23) as f32 - IMAGENET_MEAN[c] * 255.0) / (IMAGENET_STD[c] * 255.0);
            assert_eq!(v.to_bits(), expected.to_bits(), "element {i}");
        }
    }
}
