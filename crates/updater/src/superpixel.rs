//! IGEV-Stereo's superpixel upsampling: from the 1/4-resolution disparity to full resolution
//! as a weighted sum of each coarse pixel's 3x3 neighbourhood, the 9 weights per full-resolution
//! pixel a softmax of features upsampled by transposed convolutions.
//!
//! Two weight heads share the upsampling: the initial disparity's (`spx_4`, `spx_2`, `spx`, from
//! the left view's 1/4 features and 1/2 stem) and the iterations' (`spx_2_gru`, `spx_gru`, from the
//! update block's 1/4 mask features and the same stem). This is the choice beside RAFT-Stereo's
//! convex upsampling (`updater.upsampling = "superpixel"`), whose weights the update block
//! predicts at 1/4 itself.

use burn::module::Module;
use burn::nn::conv::ConvTranspose2d;
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor};
use dgstereo_core::conv_blocks::{BlockNorm, InstanceStem, UpConcat, upsample_deconv};

/// The two weight heads of the superpixel upsampling, named as in the official model.
///
/// # Shapes
/// - `features`: `[N, 96, H/4, W/4]`; `mask_features`: `[N, 32, H/4, W/4]`;
///   `stem_2`: `[N, 32, H/2, W/2]`; weights `[N, 9, H, W]`
#[derive(Module, Debug)]
pub struct SuperpixelUpsampler {
    /// 1/4 features to 24 channels (instance norm).
    pub spx_4: InstanceStem,
    /// Up to 1/2, joined with the stem: 64 channels (instance norm).
    pub spx_2: UpConcat,
    /// Up to full resolution: the initial disparity's 9 weight logits.
    pub spx: ConvTranspose2d,
    /// The mask features up to 1/2, joined with the stem: 64 channels (batch norm).
    pub spx_2_gru: UpConcat,
    /// Up to full resolution: the iterations' 9 weight logits.
    pub spx_gru: ConvTranspose2d,
}

impl SuperpixelUpsampler {
    /// The heads with fresh weights, for IGEV's widths: 96 feature channels, 32 stem and 32
    /// mask-feature channels.
    pub fn new(device: &Device) -> Self {
        Self {
            spx_4: InstanceStem::new(96, 24, 1, device),
            spx_2: UpConcat::new(24, 32, BlockNorm::Instance, device),
            spx: upsample_deconv([64, 9], true, device),
            spx_2_gru: UpConcat::new(32, 32, BlockNorm::Batch, device),
            spx_gru: upsample_deconv([64, 9], true, device),
        }
    }

    /// The initial disparity's weights from the left view's 1/4 features and 1/2 stem: the
    /// softmax over the 9 neighbours.
    pub fn initial_weights(&self, features: Tensor<4>, stem_2: Tensor<4>) -> Tensor<4> {
        let x = self.spx_2.forward(self.spx_4.forward(features), stem_2);
        softmax(self.spx.forward(x), 1)
    }

    /// An iteration's weights from the update block's 1/4 mask features and the 1/2 stem.
    pub fn iteration_weights(&self, mask_features: Tensor<4>, stem_2: Tensor<4>) -> Tensor<4> {
        softmax(self.spx_gru.forward(self.spx_2_gru.forward(mask_features, stem_2)), 1)
    }
}

/// IGEV's `context_upsample` of `disparity · 4` (the 1/4 grid's disparity in full-resolution
/// pixels): each full-resolution pixel is the `weights`-weighted sum of the 3x3 neighbourhood
/// (zero outside the image, row by row as `F.unfold` orders it) of the coarse pixel it falls in.
///
/// # Shapes
/// - `disparity`: `[N, 1, h, w]`; `weights`: `[N, 9, 4h, 4w]`; output `[N, 1, 4h, 4w]`
pub fn context_upsample(disparity: Tensor<4>, weights: Tensor<4>) -> Tensor<4> {
    let [n, _, h, w] = disparity.dims();
    let padded = disparity.mul_scalar(4.0).pad((1, 1, 1, 1), burn::tensor::ops::PadMode::Constant(0.0));
    let neighbours: Vec<Tensor<4>> =
        (0..9).map(|k| padded.clone().slice([0..n, 0..1, k / 3..k / 3 + h, k % 3..k % 3 + w])).collect();
    // Nearest x4: every coarse value repeated over its 4x4 block.
    let unfolded =
        Tensor::cat(neighbours, 1).reshape([n, 9, h, 1, w, 1]).expand([n, 9, h, 4, w, 4]).reshape([n, 9, 4 * h, 4 * w]);
    (unfolded * weights).sum_dim(1)
}

#[cfg(test)]
mod tests {
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::{from_vec, to_vec};

    use super::*;

    /// A weight of 1 on one neighbour copies that neighbour (times 4) to the pixel's whole 4x4
    /// block; the centre weight reproduces nearest upsampling; outside the image counts zero.
    #[test]
    fn context_upsample_picks_the_weighted_neighbour() {
        let device = default_device();
        let disparity = from_vec((1..=6).map(|v| v as f32).collect(), [1, 1, 2, 3], &device);
        let one_hot = |k: usize| {
            let mut w = vec![0.0; 9 * 8 * 12];
            w[k * 96..(k + 1) * 96].fill(1.0);
            from_vec(w, [1, 9, 8, 12], &device)
        };
        let centre = to_vec(context_upsample(disparity.clone(), one_hot(4)));
        assert_eq!(centre[0], 4.0);
        assert_eq!(centre[11], 12.0);
        assert_eq!(centre[12 * 7 + 11], 24.0);
        // Neighbour 5 (same row, one to the right): the last column reads beyond the image.
        let right = to_vec(context_upsample(disparity, one_hot(5)));
        assert_eq!(right[0], 8.0);
        assert_eq!(right[11], 0.0);
        assert_eq!(right[12 * 4], 20.0);
    }

    /// The heads give softmax weights at full resolution: 9 per pixel, summing to one.
    #[test]
    fn weights_are_a_distribution_over_nine_neighbours() {
        let device = default_device();
        let up = SuperpixelUpsampler::new(&device);
        let dist = burn::tensor::Distribution::Uniform(-1.0, 1.0);
        let stem = Tensor::<4>::random([1, 32, 8, 12], dist, &device);
        let w = up.iteration_weights(Tensor::random([1, 32, 4, 6], dist, &device), stem.clone());
        assert_eq!(w.dims(), [1, 9, 16, 24]);
        let sums = to_vec(w.sum_dim(1));
        assert!(sums.iter().all(|s| (s - 1.0).abs() < 1e-5), "{sums:?}");
        assert_eq!(up.initial_weights(Tensor::random([1, 96, 4, 6], dist, &device), stem).dims(), [1, 9, 16, 24]);
    }
}
