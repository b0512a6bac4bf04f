//! The encoders' options and the one place that builds the chosen layout.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::context::ContextEncoder;
use crate::depth_block::DepthFeatureInput;
use crate::feature::{FeatureEncoder, SharedFeatureHead};
use crate::layout::{Encoders, PyramidEncoders, SeparateEncoders, SharedBackbone};
use crate::norm::NormKind;
use crate::pyramid::{MobileNetPyramid, stem_2, stem_4};

/// Which encoders the network has. Each variant is a whole layout, so options that exist only
/// together (a shared trunk, a pyramid's own feature network) cannot be combined wrongly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EncoderLayout {
    /// RAFT-Stereo's separate residual feature encoder (`fnet`) and context encoder (`cnet`).
    #[default]
    Separate,
    /// RAFT-Stereo's shared backbone (its realtime model): the context encoder's trunk also
    /// feeds the feature head (`conv2`).
    SharedBackbone,
    /// IGEV-Stereo's MobileNetV2 pyramid with its image stems (`feature`, `stem_2`, `stem_4`)
    /// beside RAFT-Stereo's context encoder: four levels, the finest (1/4, 96 channels) the
    /// matching features.
    MobilenetPyramid,
}

impl EncoderLayout {
    /// Every layout, in the enum's order (a test compares it with the names serde accepts).
    pub const ALL: [Self; 3] = [Self::Separate, Self::SharedBackbone, Self::MobilenetPyramid];

    /// The layout's name as the TOML key `layout` writes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Separate => "separate",
            Self::SharedBackbone => "shared-backbone",
            Self::MobilenetPyramid => "mobilenet-pyramid",
        }
    }
}

/// Encoder options of RAFT-Stereo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Normalisation of the context encoder (`context_norm`: batch, group, instance, none).
    #[serde(default)]
    pub context_norm: NormKind,
    /// Which encoders (`layout`: `separate`, `shared-backbone`, `mobilenet-pyramid`).
    #[serde(default)]
    pub layout: EncoderLayout,
    /// Channels of the matching features (256; the MobileNetV2 pyramid's are fixed).
    #[serde(default = "default_feature_dim")]
    pub feature_dim: usize,
    /// Widths of the residual trunk's three stages in both encoders (`[64, 96, 128]`; with
    /// `layout = "mobilenet-pyramid"` the context encoder's alone); smaller widths make a
    /// CPU-trainable model, but official checkpoints need the reference's.
    #[serde(default = "default_trunk_dims")]
    pub trunk_dims: [usize; 3],
    /// Whether the encoders add a monocular network's features to their trunks, on
    /// ImageNet-normalised images (`added`: DEFOM-Stereo), or read the image alone (`none`).
    #[serde(default)]
    pub depth_features: DepthFeatureInput,
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
            layout: EncoderLayout::Separate,
            feature_dim: 256,
            trunk_dims: default_trunk_dims(),
            depth_features: DepthFeatureInput::None,
        }
    }
}

impl EncoderConfig {
    /// Everything wrong with the options, keys relative to the encoder table: zero widths, trunk
    /// widths that the group norm (`channels / 8` groups) cannot split, and monocular features
    /// in a layout other than the separate encoders (DEFOM-Stereo's encoders are separate).
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
        if self.depth_features == DepthFeatureInput::Added && self.layout != EncoderLayout::Separate {
            add(
                "depth_features",
                format!(
                    "\"added\" needs separate feature and context encoders (layout = \"separate\"), not layout = \"{}\"",
                    self.layout.name()
                ),
            );
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

    /// Builds the layout ([`EncoderLayout`]) with one `match`.
    /// `context_dims` are the GRU's hidden widths (coarsest first), `n_downsample` the `log2` of
    /// the encoders' output stride, `depth_channels` the width of the monocular features the
    /// encoders add (with `depth_features = "added"`).
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] keyed `depth_features` when they add features and
    /// `depth_channels` is `None`, keyed `layout` when the MobileNetV2 pyramid (fixed
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
        Ok(match self.layout {
            EncoderLayout::Separate => Encoders::Separate(SeparateEncoders {
                fnet: FeatureEncoder::new(self.feature_dim, trunk, NormKind::Instance, n_downsample, depth, device),
                cnet: cnet(depth),
                normalisation: self.depth_features.normalisation(),
            }),
            EncoderLayout::SharedBackbone => Encoders::Shared(SharedBackbone {
                cnet: cnet(None),
                conv2: SharedFeatureHead::new(trunk[2], self.feature_dim, device),
            }),
            EncoderLayout::MobilenetPyramid => {
                if n_downsample != 2 {
                    return Err(dgstereo_core::Error::config(
                        "layout",
                        format!(
                            "\"mobilenet-pyramid\" gives features at 1/4: it needs n_downsample = 2, not {n_downsample}"
                        ),
                    ));
                }
                // The official constructor's order: `cnet`, then `feature`, `stem_2`, `stem_4`.
                let cnet = cnet(None);
                Encoders::Pyramid(PyramidEncoders {
                    cnet,
                    feature: MobileNetPyramid::new(device),
                    stem_2: stem_2(device),
                    stem_4: stem_4(device),
                })
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;
    use serde::de::value::{Error, MapDeserializer, StrDeserializer};

    use super::*;

    /// `ALL` lists every layout serde accepts, once, in the enum's order, named as TOML writes it.
    #[test]
    fn every_layout_is_listed() {
        let accepted = dgstereo_core::serde_names::accepted_names::<EncoderLayout>().unwrap();
        let listed: Vec<&str> = EncoderLayout::ALL.iter().map(|l| l.name()).collect();
        assert_eq!(listed, accepted);
        for layout in EncoderLayout::ALL {
            assert_eq!(EncoderLayout::deserialize(StrDeserializer::<Error>::new(layout.name())), Ok(layout));
        }
    }

    /// A table that still names the layout by `shared_backbone` or `feature_network` is refused
    /// by the key, and the message lists `layout`, the key that says it; nothing is defaulted.
    #[test]
    fn the_keys_layout_replaces_are_refused_naming_layout() {
        for key in ["shared_backbone", "feature_network"] {
            let table = MapDeserializer::<_, Error>::new(std::iter::once((key, "true")));
            let message = EncoderConfig::deserialize(table).expect_err(key).to_string();
            assert!(message.contains(key) && message.contains("`layout`"), "{message}");
        }
    }

    /// Monocular features need the separate encoders: every other layout is refused by
    /// `depth_features`, naming the layout.
    #[test]
    fn added_depth_features_need_the_separate_layout() {
        for layout in EncoderLayout::ALL {
            let config = EncoderConfig { layout, depth_features: DepthFeatureInput::Added, ..Default::default() };
            let problems = config.problems();
            match layout {
                EncoderLayout::Separate => assert!(problems.is_empty(), "{problems:?}"),
                _ => assert!(
                    problems.iter().any(|p| p.key == "depth_features" && p.reason.contains(layout.name())),
                    "{problems:?}"
                ),
            }
        }
    }
}
