//! The shared front end of the learned fusions: lifting the image and the depth prior to features.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::{Device, Tensor};
use dgstereo_core::{Problem, Result};
use dgstereo_kernels::{Numerics, conv2d_forward};

use crate::depth::normalize_depth;
use crate::init::{RGB, identity_padded_projection};

/// Two 1x1 convolutions: the RGB image to `F` channels (`F_i`) and the normalised depth prior to
/// `F` channels (`F_d`).
///
/// `F_i`'s first three channels start as a copy of the image (see [`crate::init`]).
#[derive(Module, Debug)]
pub struct FeatureProjection {
    /// 1x1 conv, `3 -> F`.
    pub image: Conv2d,
    /// 1x1 conv, `1 -> F`.
    pub depth: Conv2d,
}

/// The problem with a feature channel count below 3 (the identity initialisation needs room for
/// the RGB channels), keyed `features`.
pub(crate) fn features_problem(features: usize) -> Option<Problem> {
    (features < RGB).then(|| Problem::new("features", format!("{features} is below {RGB}")))
}

impl FeatureProjection {
    /// Builds the two projections to `features` channels.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] naming `features` when `features < 3`.
    pub fn new(features: usize, device: &Device) -> Result<Self> {
        Problem::first(features_problem(features))?;
        let image = Conv2dConfig::new([RGB, features], [1, 1]).init(device);
        let depth = Conv2dConfig::new([1, features], [1, 1]).init(device);
        Ok(Self { image: identity_padded_projection(image), depth })
    }

    /// The feature channel count `F`.
    pub fn features(&self) -> usize {
        self.image.weight.dims()[0]
    }

    /// `(F_i, F_d)`. The depth is normalised per image with [`normalize_depth`] (and resized to
    /// the image's size when it differs) before its projection.
    ///
    /// # Shapes
    /// - `image`: `[N, 3, H, W]`, 0..255
    /// - `depth`: `[N, 1, H_d, W_d]`, relative depth
    /// - outputs: `[N, F, H, W]` each
    pub fn forward(&self, image: Tensor<4>, depth: Tensor<4>) -> (Tensor<4>, Tensor<4>) {
        let [_, _, h, w] = image.dims();
        let depth = normalize_depth(depth, [h, w]);
        (
            conv2d_forward(&self.image, image, Numerics::Sensitive),
            conv2d_forward(&self.depth, depth, Numerics::Sensitive),
        )
    }
}
