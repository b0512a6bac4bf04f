//! IGEV-Stereo's `FeatureAtt`: the image features of one scale gate a cost volume of that scale,
//! channel by channel, through a sigmoid.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::activation::sigmoid;
use burn::tensor::{Device, Tensor};

use dgstereo_core::conv_blocks::{BasicConv, BlockNorm};

/// `sigmoid(expand(reduce(feat)))` broadcast over the disparities, times the volume. `reduce`
/// and `expand` are the reference's `feat_att.0` (a `BasicConv`, 1x1 to half the features'
/// channels) and `feat_att.1` (a 1x1 convolution with bias to the volume's channels).
///
/// # Shapes
/// - `cv`: `[N, C_cv, D, H, W]`; `feat`: `[N, C_feat, H, W]`; output as `cv`
#[derive(Module, Debug)]
pub struct FeatureAttention {
    /// 1x1 `BasicConv` to `C_feat / 2` channels (`feat_att.0`).
    pub reduce: BasicConv,
    /// 1x1 convolution to `C_cv` channels (`feat_att.1`).
    pub expand: Conv2d,
}

impl FeatureAttention {
    /// The gate of a volume of `volume_channels` by features of `feature_channels`.
    pub fn new(volume_channels: usize, feature_channels: usize, device: &Device) -> Self {
        let half = feature_channels / 2;
        Self {
            reduce: BasicConv::new([feature_channels, half], 1, 1, 0, BlockNorm::Batch, device),
            expand: Conv2dConfig::new([half, volume_channels], [1, 1]).init(device),
        }
    }

    /// The gated volume.
    pub fn forward(&self, cv: Tensor<5>, feat: Tensor<4>) -> Tensor<5> {
        let gate = sigmoid(self.expand.forward(self.reduce.forward(feat))).unsqueeze_dim::<5>(2);
        gate * cv
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::to_vec;

    use super::*;

    /// The gate lies in (0, 1) and is the same at every disparity of a pixel: a volume of ones
    /// comes out as the gate itself, repeated along the disparities.
    #[test]
    fn the_gate_is_shared_by_every_disparity() {
        let device = default_device();
        let att = FeatureAttention::new(3, 8, &device);
        let feat = Tensor::<4>::random([1, 8, 4, 5], Distribution::Normal(0.0, 1.0), &device);
        let gated = att.forward(Tensor::ones([1, 3, 6, 4, 5], &device), feat);
        assert_eq!(gated.dims(), [1, 3, 6, 4, 5]);
        let first = to_vec(gated.clone().narrow(2, 0, 1));
        assert!(first.iter().all(|v| *v > 0.0 && *v < 1.0));
        for d in 1..6 {
            assert_eq!(to_vec(gated.clone().narrow(2, d, 1)), first, "disparity {d}");
        }
    }
}
