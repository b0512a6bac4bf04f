//! IGEV-Stereo's geometry encoding volume: match features, the group-wise correlation volume,
//! its 3-D aggregation and the classifier whose soft-argmin starts the update loop.

use burn::module::Module;
use burn::nn::PaddingConfig3d;
use burn::nn::conv::{Conv2d, Conv2dConfig, Conv3d, Conv3dConfig};
use burn::tensor::{Device, Tensor};
use dgstereo_core::Problem;
use serde::{Deserialize, Serialize};

use dgstereo_core::conv_blocks::{BasicConv, BlockNorm};

use crate::basic_conv::BasicConv3d;
use crate::feature_attention::FeatureAttention;
use crate::hourglass::Hourglass;

/// Options of the geometry encoding volume (`[model.correlation.geometry]`), IGEV-Stereo's
/// defaults.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryVolume {
    /// The largest disparity at full resolution (`max_disp`, 192); the volume holds
    /// `max_disp / 4` disparities at the 1/4 grid.
    #[serde(default = "default_max_disp")]
    pub max_disp: usize,
    /// Channel groups of the correlation (8).
    #[serde(default = "default_groups")]
    pub groups: usize,
}

fn default_max_disp() -> usize {
    192
}
fn default_groups() -> usize {
    8
}

impl Default for GeometryVolume {
    fn default() -> Self {
        Self { max_disp: default_max_disp(), groups: default_groups() }
    }
}

/// Channels of IGEV-Stereo's left features per scale (1/4 with the image stem, 1/8, 1/16,
/// 1/32), which the match features and the volume's gates read.
pub const FEATURE_CHANNELS: [usize; 4] = [96, 64, 192, 160];

impl GeometryVolume {
    /// Disparities of the volume at the 1/4 grid, `max_disp / 4`.
    pub fn disparities(&self) -> usize {
        self.max_disp / 4
    }

    /// Bytes of the largest tensors the volume keeps alive together for a batch of `n` at an
    /// `h x w` 1/4 grid, an estimate for the memory budget: the group-wise volume three times
    /// (it, `corr_stem`'s output and the gated volume), the hourglass's widest activations (its
    /// 16-channel first level at half the disparities and size, 2·D per 1/4 pixel, and its
    /// 8-channel output at full size, 8·D), the lookup's stored geometry pyramid (8 channels, the
    /// disparities and their half: 12·D) and the all-pairs correlation with its half
    /// (1.5·`w` per pixel), all f32. 8 groups of 48 disparities at 1/4 of 384x448: 102 MB; of a 2160x3840 frame: 7.6 GB.
    pub fn volume_bytes(&self, n: usize, h: usize, w: usize) -> usize {
        let d = self.disparities();
        let per_pixel = d * (3 * self.groups + 2 + 8 + 12) + w + w / 2;
        4 * n * h * w * per_pixel
    }

    /// Everything wrong with the options, keys relative to its table: `max_disp` must give a
    /// positive multiple of 8 disparities at 1/4 (the aggregation halves them three times), and
    /// `groups` must divide the match features' 96 channels.
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        if self.max_disp == 0 || !self.max_disp.is_multiple_of(32) {
            problems.push(Problem::new("max_disp", format!("{} is not a positive multiple of 32", self.max_disp)));
        }
        if self.groups == 0 || !FEATURE_CHANNELS[0].is_multiple_of(self.groups) {
            problems.push(Problem::new("groups", format!("{} does not divide the 96 match channels", self.groups)));
        }
        problems
    }

    /// Builds the modules with fresh weights.
    pub fn init(&self, device: &Device) -> GeometryEncoding {
        let [f4, f8, f16, f32] = FEATURE_CHANNELS;
        let g = self.groups;
        GeometryEncoding {
            conv: BasicConv::new([f4, f4], 3, 1, 1, BlockNorm::Instance, device),
            desc: Conv2dConfig::new([f4, f4], [1, 1]).init(device),
            corr_stem: BasicConv3d::new([g, g], 3, 1, 1, device),
            corr_feature_att: FeatureAttention::new(g, f4, device),
            cost_agg: Hourglass::new(g, [f8, f16, f32], device),
            classifier: Conv3dConfig::new([g, 1], [3; 3])
                .with_padding(PaddingConfig3d::Explicit(1, 1, 1))
                .with_bias(false)
                .init(device),
            disparities: self.disparities(),
            groups: g,
        }
    }
}

/// The modules of the geometry encoding volume, named as in the reference (`conv`, `desc`,
/// `corr_stem`, `corr_feature_att`, `cost_agg`, `classifier`).
#[derive(Module, Debug)]
pub struct GeometryEncoding {
    /// `BasicConv_IN` 3x3 on the 1/4 features.
    pub conv: BasicConv,
    /// 1x1 giving the match features.
    pub desc: Conv2d,
    /// 3x3x3 `BasicConv` on the correlation volume.
    pub corr_stem: BasicConv3d,
    /// The 1/4 features' gate of the volume.
    pub corr_feature_att: FeatureAttention,
    /// The hourglass aggregation.
    pub cost_agg: Hourglass,
    /// 3x3x3 to one channel: the logits of the initial disparity.
    pub classifier: Conv3d,
    /// Disparities at the 1/4 grid.
    pub disparities: usize,
    /// Channel groups of the correlation.
    pub groups: usize,
}

/// What [`GeometryEncoding::forward`] computes.
///
/// # Shapes
/// - `match_left`, `match_right`: `[N, 96, H, W]` (the 1/4 grid)
/// - `corr_stem`, `corr_feature_att`, `volume`: `[N, groups, D, H, W]`
/// - `logits`: `[N, D, H, W]`
#[derive(Debug, Clone)]
pub struct GeometryOutput {
    /// The left match features (`desc(conv(features[0]))`).
    pub match_left: Tensor<4>,
    /// The right match features.
    pub match_right: Tensor<4>,
    /// The correlation volume after `corr_stem`.
    pub corr_stem: Tensor<5>,
    /// After the 1/4 features' gate.
    pub corr_feature_att: Tensor<5>,
    /// The geometry encoding volume (after `cost_agg`).
    pub volume: Tensor<5>,
    /// The classifier's logits per disparity.
    pub logits: Tensor<4>,
}

impl GeometryEncoding {
    /// Match features of the 1/4 features of one view.
    pub fn match_features(&self, features: Tensor<4>) -> Tensor<4> {
        self.desc.forward(self.conv.forward(features))
    }

    /// The volume of the left pyramid `left` (1/4, 1/8, 1/16, 1/32; the 1/4 level with the
    /// image stem's channels) against the right view's 1/4 features `right`.
    pub fn forward(&self, left: &[Tensor<4>], right: Tensor<4>) -> GeometryOutput {
        let match_left = self.match_features(left[0].clone());
        let match_right = self.match_features(right);
        let gwc = groupwise_correlation_volume(match_left.clone(), match_right.clone(), self.disparities, self.groups);
        let corr_stem = self.corr_stem.forward(gwc);
        let corr_feature_att = self.corr_feature_att.forward(corr_stem.clone(), left[0].clone());
        let volume = self.cost_agg.forward(corr_feature_att.clone(), left);
        let logits = self.classifier.forward(volume.clone()).squeeze_dim::<4>(1);
        GeometryOutput { match_left, match_right, corr_stem, corr_feature_att, volume, logits }
    }
}

/// `build_gwc_volume`: for each disparity `d < disparities` and group `g`, the mean over the
/// group's channels of `left[x] · right[x - d]`, zero where `x < d`.
///
/// # Shapes
/// - `left`, `right`: `[N, C, H, W]` with `groups` dividing `C`; output `[N, groups, D, H, W]`
pub fn groupwise_correlation_volume(left: Tensor<4>, right: Tensor<4>, disparities: usize, groups: usize) -> Tensor<5> {
    let [n, c, h, w] = left.dims();
    let device = left.device();
    let planes = (0..disparities)
        .map(|d| {
            let plane = Tensor::<5>::zeros([n, groups, 1, h, w], &device);
            if d >= w {
                return plane;
            }
            let product = left.clone().narrow(3, d, w - d) * right.clone().narrow(3, 0, w - d);
            let cost = product.reshape([n, groups, c / groups, h, w - d]).mean_dim(2);
            plane.slice_assign([0..n, 0..groups, 0..1, 0..h, d..w], cost)
        })
        .collect();
    Tensor::cat(planes, 2)
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::to_vec;

    use super::*;

    /// Each entry is the mean of its group's channel products at `x` and `x - d`, zero where the
    /// right view has no column `x - d`.
    #[test]
    fn the_groupwise_volume_is_the_references() {
        let device = default_device();
        let (n, c, h, w, groups, disparities) = (1, 6, 2, 5, 3, 4);
        let left = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let right = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let volume = to_vec(groupwise_correlation_volume(left.clone(), right.clone(), disparities, groups));
        let (l, r) = (to_vec(left), to_vec(right));
        let at = |v: &[f32], ch: usize, y: usize, x: usize| v[(ch * h + y) * w + x];
        for g in 0..groups {
            for d in 0..disparities {
                for y in 0..h {
                    for x in 0..w {
                        let expected = if x < d {
                            0.0
                        } else {
                            (0..2).map(|k| at(&l, 2 * g + k, y, x) * at(&r, 2 * g + k, y, x - d)).sum::<f32>() / 2.0
                        };
                        let got = volume[((g * disparities + d) * h + y) * w + x];
                        assert!((got - expected).abs() < 1e-6, "g {g} d {d} y {y} x {x}: {got} vs {expected}");
                    }
                }
            }
        }
    }

    /// The options' problems name their keys; the defaults have none.
    #[test]
    fn bad_options_are_named() {
        assert!(GeometryVolume::default().problems().is_empty());
        assert_eq!(GeometryVolume { max_disp: 100, groups: 8 }.problems()[0].key, "max_disp");
        assert_eq!(GeometryVolume { max_disp: 192, groups: 7 }.problems()[0].key, "groups");
    }
}
