//! The `depth-anything-v2` prior provider.
//!
//! The official network on both views: the left and right images of a batch of `N` pairs are
//! stacked into one batch of `2N` and go through [`DepthAnythingV2::infer`] (the official
//! `infer_image`: resize so the shorter side is at least `input_size` with both sides multiples
//! of 14, ImageNet normalisation, network, bilinear resize back). Grey images are repeated to
//! three channels. The weights come from `prior.weights` (or `--prior-weights`); a missing
//! checkpoint is an error naming that key, never a fallback to another provider. The output is
//! detached: the prior is an input of the stereo model, not something it trains.

use std::path::Path;

use burn::tensor::{Device, Tensor};
use dgstereo_core::{Error, Result};

use super::{DepthAnythingV2, DepthAnythingV2Encoder};
use crate::{DepthPrior, PriorInput, PriorProvider};

/// Runs Depth Anything V2 on both views of a batch (in one batch of `2N` images).
#[derive(Debug, Clone)]
pub struct DepthAnythingV2Prior {
    model: DepthAnythingV2,
    input_size: usize,
}

impl DepthAnythingV2Prior {
    /// Wraps a loaded model; `input_size` is the official `--input-size` (518).
    pub fn new(model: DepthAnythingV2, input_size: usize) -> Self {
        Self { model, input_size }
    }

    /// Loads the checkpoint `weights`; `encoder` is checked against it, or read from it when
    /// `None`. Errors name the configuration key (`prior.weights`, `prior.encoder`).
    pub fn load(
        weights: &Path,
        encoder: Option<DepthAnythingV2Encoder>,
        input_size: usize,
        device: &Device,
    ) -> Result<Self> {
        if input_size < super::dinov2::PATCH_SIZE {
            return Err(Error::config("prior.input_size", format!("{input_size}: must be at least 14")));
        }
        if !weights.is_file() {
            return Err(Error::config(
                "prior.weights",
                format!(
                    "'{}': no such file (download depth_anything_v2_vit{{s,b,l}}.pth from the official release; \
                     there is no fallback)",
                    weights.display()
                ),
            ));
        }
        let detected = super::checkpoint::detect_encoder(weights)?;
        if let Some(encoder) = encoder
            && encoder != detected
        {
            return Err(Error::config(
                "prior.encoder",
                format!("'{encoder}' but prior.weights = '{}' holds a {detected} checkpoint", weights.display()),
            ));
        }
        Ok(Self::new(DepthAnythingV2::load(detected, weights, device)?, input_size))
    }

    /// The wrapped model.
    pub fn model(&self) -> &DepthAnythingV2 {
        &self.model
    }
}

/// Grayscale images become RGB by repeating the channel.
fn as_rgb(x: Tensor<4>) -> Result<Tensor<4>> {
    match x.dims()[1] {
        3 => Ok(x),
        1 => Ok(x.repeat_dim(1, 3)),
        c => Err(Error::Shape(format!("depth-anything-v2 prior: images have {c} channels, expected 3 or 1"))),
    }
}

impl PriorProvider for DepthAnythingV2Prior {
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>> {
        let [n, _, h, w] = input.left.dims();
        if input.right.dims()[0] != n || input.right.dims()[2..] != [h, w] {
            return Err(Error::Shape(format!(
                "depth-anything-v2 prior: left {:?} and right {:?} differ",
                input.left.dims(),
                input.right.dims()
            )));
        }
        if h == 0 || w == 0 || n == 0 {
            return Err(Error::Shape(format!("depth-anything-v2 prior: empty images {:?}", input.left.dims())));
        }
        let both = Tensor::cat(vec![as_rgb(input.left.clone())?, as_rgb(input.right.clone())?], 0).detach();
        let depth = self.model.infer(both, self.input_size)?.detach();
        Ok(Some(DepthPrior { left: depth.clone().narrow(0, 0, n), right: depth.narrow(0, n, n) }))
    }
}
