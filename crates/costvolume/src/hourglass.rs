//! IGEV-Stereo's cost aggregation (`hourglass`): a 3-D encoder-decoder over the group-wise
//! correlation volume, each scale gated by the left image's features of that scale.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::basic_conv::{BasicConv3d, BasicDeconv3d};
use crate::feature_attention::FeatureAttention;

/// Three stride-2 stages (`conv1..3`, each two `BasicConv`s, to 2, 4 and 6 times the input
/// channels), each gated by the features of its scale (1/8, 1/16, 1/32 of the image); two
/// doubling transposed convolutions back, each joined with the encoder's output of its scale
/// and aggregated (`agg_0`, `agg_1`: 1x1 then two 3x3) and gated again; a last transposed
/// convolution to 8 channels without norm or activation (`conv1_up`).
///
/// # Shapes
/// - `x`: `[N, C, D, H, W]` with `D`, `H`, `W` multiples of 8; `features[1..=3]`: the left
///   features at `H/2`, `H/4`, `H/8` (`[N, feature_channels[i], ...]`)
/// - output `[N, 8, D, H, W]`
#[derive(Module, Debug)]
pub struct Hourglass {
    /// Down to 1/2 of the volume, `2C` channels.
    pub conv1: Vec<BasicConv3d>,
    /// Down to 1/4, `4C` channels.
    pub conv2: Vec<BasicConv3d>,
    /// Down to 1/8, `6C` channels.
    pub conv3: Vec<BasicConv3d>,
    /// Up from 1/8 to 1/4, `4C` channels.
    pub conv3_up: BasicDeconv3d,
    /// Up from 1/4 to 1/2, `2C` channels.
    pub conv2_up: BasicDeconv3d,
    /// Up from 1/2 to the input's size, 8 channels, no norm or activation.
    pub conv1_up: BasicDeconv3d,
    /// Aggregation at 1/4 after the skip connection.
    pub agg_0: Vec<BasicConv3d>,
    /// Aggregation at 1/2 after the skip connection.
    pub agg_1: Vec<BasicConv3d>,
    /// Gate at 1/2 (down).
    pub feature_att_8: FeatureAttention,
    /// Gate at 1/4 (down).
    pub feature_att_16: FeatureAttention,
    /// Gate at 1/8.
    pub feature_att_32: FeatureAttention,
    /// Gate at 1/4 (up).
    pub feature_att_up_16: FeatureAttention,
    /// Gate at 1/2 (up).
    pub feature_att_up_8: FeatureAttention,
}

/// A stride-2 `BasicConv` then a stride-1 one, `[cin, cout]`.
fn down(cin: usize, cout: usize, device: &Device) -> Vec<BasicConv3d> {
    vec![BasicConv3d::new([cin, cout], 3, 2, 1, device), BasicConv3d::new([cout, cout], 3, 1, 1, device)]
}

/// A 1x1 `BasicConv` from `cin` to `cout` then two 3x3 ones.
fn aggregation(cin: usize, cout: usize, device: &Device) -> Vec<BasicConv3d> {
    vec![
        BasicConv3d::new([cin, cout], 1, 1, 0, device),
        BasicConv3d::new([cout, cout], 3, 1, 1, device),
        BasicConv3d::new([cout, cout], 3, 1, 1, device),
    ]
}

fn sequence(layers: &[BasicConv3d], x: Tensor<5>) -> Tensor<5> {
    layers.iter().fold(x, |x, layer| layer.forward(x))
}

impl Hourglass {
    /// The aggregation of a volume of `c` channels, gated by features of `feature_channels` at
    /// 1/8, 1/16 and 1/32 of the image (IGEV-Stereo: 8 channels, features 64, 192, 160).
    pub fn new(c: usize, feature_channels: [usize; 3], device: &Device) -> Self {
        let [f8, f16, f32] = feature_channels;
        Self {
            conv1: down(c, 2 * c, device),
            conv2: down(2 * c, 4 * c, device),
            conv3: down(4 * c, 6 * c, device),
            conv3_up: BasicDeconv3d::new([6 * c, 4 * c], true, device),
            conv2_up: BasicDeconv3d::new([4 * c, 2 * c], true, device),
            conv1_up: BasicDeconv3d::new([2 * c, 8], false, device),
            agg_0: aggregation(8 * c, 4 * c, device),
            agg_1: aggregation(4 * c, 2 * c, device),
            feature_att_8: FeatureAttention::new(2 * c, f8, device),
            feature_att_16: FeatureAttention::new(4 * c, f16, device),
            feature_att_32: FeatureAttention::new(6 * c, f32, device),
            feature_att_up_16: FeatureAttention::new(4 * c, f16, device),
            feature_att_up_8: FeatureAttention::new(2 * c, f8, device),
        }
    }

    /// The aggregated volume (the geometry encoding volume), in the reference's order.
    pub fn forward(&self, x: Tensor<5>, features: &[Tensor<4>]) -> Tensor<5> {
        let conv1 = self.feature_att_8.forward(sequence(&self.conv1, x), features[1].clone());
        let conv2 = self.feature_att_16.forward(sequence(&self.conv2, conv1.clone()), features[2].clone());
        let conv3 = self.feature_att_32.forward(sequence(&self.conv3, conv2.clone()), features[3].clone());
        let conv3_up = self.conv3_up.forward(conv3);
        let conv2 = sequence(&self.agg_0, Tensor::cat(vec![conv3_up, conv2], 1));
        let conv2 = self.feature_att_up_16.forward(conv2, features[2].clone());
        let conv2_up = self.conv2_up.forward(conv2);
        let conv1 = sequence(&self.agg_1, Tensor::cat(vec![conv2_up, conv1], 1));
        let conv1 = self.feature_att_up_8.forward(conv1, features[1].clone());
        self.conv1_up.forward(conv1)
    }
}
