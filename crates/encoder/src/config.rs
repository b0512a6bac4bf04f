//! The encoders' options and the one place that builds the chosen layout.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::context::ContextEncoder;
use crate::depth_block::DepthFeatureInput;
use crate::feature::{FeatureEncoder, SharedFeatureHead};
use crate::layout::{Encoders, PyramidEncoders, SeparateEncoders, SharedBackbone};
use crate::norm::NormKind;
use crate::pyramid::{MobileNetPyramid, stem_2, stem_4};

/// Which network gives the matching features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FeatureNetwork {
    /// RAFT-Stereo's residual feature encoder (`fnet`), or the shared backbone's head.
    #[default]
    Residual,
    /// IGEV-Stereo's MobileNetV2 pyramid with its image stems (`feature`, `stem_2`, `stem_4`):
    /// four levels, the finest (1/4, 96 channels) the matching features.
    MobilenetPyramid,
}

/// Encoder options of RAFT-Stereo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Normalisation of the context encoder (`context_norm`: batch, group, instance, none).
    #[serde(default)]
    pub context_norm: NormKind,
    /// One trunk for context and features (`shared_backbone`).
    #[serde(default)]
    pub shared_backbone: bool,
    /// Channels of the matching features (256).
    #[serde(default = "default_feature_dim")]
    pub feature_dim: usize,
    /// Widths of the residual trunk's three stages in both encoders (`[64, 96, 128]`); smaller
    /// widths make a CPU-trainable model, but official checkpoints need the reference's.
    #[serde(default = "default_trunk_dims")]
    pub trunk_dims: [usize; 3],
    /// Whether the encoders add a monocular network's features to their trunks, on
    /// ImageNet-normalised images (`added`: DEFOM-Stereo), or read the image alone (`none`).
    #[serde(default)]
    pub depth_features: DepthFeatureInput,
    /// The network of the matching features (`residual`: RAFT-Stereo's; `mobilenet-pyramid`:
    /// IGEV-Stereo's, whose `feature_dim` is fixed and whose `trunk_dims` are the context
    /// encoder's alone).
    #[serde(default)]
    pub feature_network: FeatureNetwork,
}

fn default_feature_dim() -> usize {
    256
}

fn default_trunk_dims() -> [usize; 3] {
    [64, 96, 128]
}

impl Default for EncoderConfig {
    fn default() -> Self {
        Self {
            context_norm: NormKind::Batch,
            shared_backbone: false,
            feature_dim: 256,
            trunk_dims: default_trunk_dims(),
            depth_features: DepthFeatureInput::None,
            feature_network: FeatureNetwork::Residual,
        }
    }
}

impl EncoderConfig {
    /// Everything wrong with the options, keys relative to the encoder table: zero widths, trunk
    /// widths that the group norm (`channels / 8` groups) cannot split, and monocular features
    /// with the shared backbone (DEFOM-Stereo's encoders are separate).
    pub fn problems(&self) -> Vec<dgstereo_core::Problem> {
        let mut problems = Vec::new();
        let mut add = |key: &str, reason: String| problems.push(dgstereo_core::Problem::new(key, reason));
        if self.feature_dim == 0 {
            add("feature_dim", "must be positive".into());
        }
        if self.trunk_dims.contains(&0) {
            add("trunk_dims", format!("{:?}: every width must be positive", self.trunk_dims));
        } else if self.context_norm == NormKind::Group
            && let Some(c) = self.trunk_dims.iter().find(|&&c| c < 8 || c % (c / 8) != 0)
        {
            add(
                "trunk_dims",
                format!(
                    "{:?}: with context_norm = \"group\" ({c} / 8 groups) every width must be at least 8 and \
                     divisible by its group count",
                    self.trunk_dims
                ),
            );
        }
        if self.depth_features == DepthFeatureInput::Added && self.shared_backbone {
            add(
                "depth_features",
                "\"added\" needs separate feature and context encoders (shared_backbone = false)".into(),
            );
        }
        if self.feature_network == FeatureNetwork::MobilenetPyramid {
            if self.shared_backbone {
                add(
                    "feature_network",
                    "\"mobilenet-pyramid\" has its own feature network: it needs shared_backbone = false".into(),
                );
            }
            if self.depth_features == DepthFeatureInput::Added {
                add(
                    "feature_network",
                    "\"mobilenet-pyramid\" adds no monocular features (depth_features = \"none\")".into(),
                );
            }
        }
        problems
    }

    /// Checks the options.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] with the first of [`problems`](Self::problems), its key
    /// relative to the encoder table.
    pub fn validate(&self) -> dgstereo_core::Result<()> {
        dgstereo_core::Problem::first(self.problems())
    }

    /// Builds the layout: separate feature and context encoders, or one shared backbone.
    /// `context_dims` are the GRU's hidden widths (coarsest first), `n_downsample` the `log2` of
    /// the encoders' output stride, `depth_channels` the width of the monocular features the
    /// encoders add (with `depth_features = "added"`).
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] keyed `depth_features` when they add features and
    /// `depth_channels` is `None`, keyed `feature_network` when the MobileNetV2 pyramid (fixed
    /// at stride 4) meets another `n_downsample` than 2.
    pub fn init(
        &self,
        context_dims: [usize; 3],
        n_downsample: usize,
        depth_channels: Option<usize>,
        device: &Device,
    ) -> dgstereo_core::Result<Encoders> {
        let depth = match (self.depth_features, depth_channels) {
            (DepthFeatureInput::None, _) => None,
            (DepthFeatureInput::Added, Some(channels)) => Some(channels),
            (DepthFeatureInput::Added, None) => {
                return Err(dgstereo_core::Error::config(
                    "depth_features",
                    "\"added\" needs a monocular network's features (model.monocular)",
                ));
            }
        };
        // Built in the order of the reference's constructor (`fnet`, `cnet`, `conv2`), which is
        // the order fresh weights are drawn in.
        let trunk = self.trunk_dims;
        let cnet = |depth| ContextEncoder::new(context_dims, trunk, self.context_norm, n_downsample, depth, device);
        if self.feature_network == FeatureNetwork::MobilenetPyramid {
            if n_downsample != 2 {
                return Err(dgstereo_core::Error::config(
                    "feature_network",
                    format!(
                        "\"mobilenet-pyramid\" gives features at 1/4: it needs n_downsample = 2, not {n_downsample}"
                    ),
                ));
            }
            // The official constructor's order: `cnet`, then `feature`, `stem_2`, `stem_4`.
            let cnet = cnet(None);
            return Ok(Encoders::Pyramid(PyramidEncoders {
                cnet,
                feature: MobileNetPyramid::new(device),
                stem_2: stem_2(device),
                stem_4: stem_4(device),
            }));
        }
        Ok(match self.shared_backbone {
            false => Encoders::Separate(SeparateEncoders {
                fnet: FeatureEncoder::new(self.feature_dim, trunk, NormKind::Instance, n_downsample, depth, device),
                cnet: cnet(depth),
                normalisation: self.depth_features.normalisation(),
            }),
            true => Encoders::Shared(SharedBackbone {
                cnet: cnet(None),
                conv2: SharedFeatureHead::new(trunk[2], self.feature_dim, device),
            }),
        })
    }
}
