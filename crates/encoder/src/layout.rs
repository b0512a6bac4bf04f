//! The encoder layouts: separate feature and context encoders, or a shared backbone.

use burn::module::Module;
use burn::tensor::Tensor;
use dgstereo_core::conv_blocks::InstanceStem;
use dgstereo_core::{Error, MonocularFeatures, Probe, Result};
use dgstereo_kernels::Numerics;

use crate::context::ContextEncoder;
use crate::depth_block::InputNormalisation;
use crate::feature::{FeatureEncoder, SharedFeatureHead};
use crate::pyramid::{FeaturePyramid, MobileNetPyramid, feature_pyramid};
use crate::{ContextExtractor, ContextFeatures};

/// What the encoders give the rest of the network.
///
/// # Shapes
/// - `fmap1`, `fmap2`: `[N, C, H/f, W/f]`; `context`: see [`ContextFeatures`]
#[derive(Debug, Clone)]
pub struct Encoded {
    /// Matching features of the left view.
    pub fmap1: Tensor<4>,
    /// Matching features of the right view.
    pub fmap2: Tensor<4>,
    /// Context of the left view per GRU level, finest first.
    pub context: ContextFeatures,
    /// The left view's feature pyramid and 1/2 stem, from encoders that build one (IGEV-Stereo's;
    /// `fmap1` is then its finest level).
    pub pyramid: Option<FeaturePyramid>,
}

/// The images the encoders see, RGB in 0..255 (`[N, 3, H, W]` each).
#[derive(Debug, Clone)]
pub struct EncoderInputs {
    /// The left view for the context (the fused image, where a fusion runs).
    pub context_left: Tensor<4>,
    /// The left view for the matching features.
    pub features_left: Tensor<4>,
    /// The right view for the matching features.
    pub features_right: Tensor<4>,
    /// A monocular network's features, for encoders that add them (DEFOM-Stereo).
    pub depth: Option<MonocularFeatures>,
}

/// RAFT-Stereo's two encoders, each with its own trunk (the reference's `fnet` and `cnet`).
#[derive(Module, Debug)]
pub struct SeparateEncoders {
    /// Feature encoder.
    pub fnet: FeatureEncoder,
    /// Context encoder.
    pub cnet: ContextEncoder,
    /// How images become the encoders' input.
    #[module(skip)]
    pub normalisation: InputNormalisation,
}

/// The shared-backbone variant: the context encoder's trunk also feeds the feature head (the
/// reference's top-level `conv2`).
#[derive(Module, Debug)]
pub struct SharedBackbone {
    /// Context encoder, whose trunk both views pass.
    pub cnet: ContextEncoder,
    /// Feature head on the trunk.
    pub conv2: SharedFeatureHead,
}

/// IGEV-Stereo's encoders: the MobileNetV2 feature pyramid (`feature`) with the image stems
/// (`stem_2`, `stem_4`) for both views, and RAFT-Stereo's context encoder (`cnet`, batch norm) for
/// the left view. The matching features are the pyramid's finest level joined with `stem_4`.
#[derive(Module, Debug)]
pub struct PyramidEncoders {
    /// The feature pyramid network.
    pub feature: MobileNetPyramid,
    /// The 1/2 image stem.
    pub stem_2: InstanceStem,
    /// The 1/4 image stem.
    pub stem_4: InstanceStem,
    /// Context encoder (the official `MultiBasicEncoder`; its heads `outputs04/08/16` are
    /// `outputs08/16/32` here, named after RAFT-Stereo's strides).
    pub cnet: ContextEncoder,
}

/// A built encoder layout, chosen by [`EncoderConfig`](crate::EncoderConfig).
// One per network, its variants' sizes are the modules' own: boxing them would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Encoders {
    /// Separate feature and context encoders.
    Separate(SeparateEncoders),
    /// One trunk for both.
    Shared(SharedBackbone),
    /// IGEV-Stereo's feature pyramid and context encoder.
    Pyramid(PyramidEncoders),
}

impl Encoders {
    /// The context encoder (either layout has one).
    pub fn context_encoder(&self) -> &ContextEncoder {
        match self {
            Self::Separate(e) => &e.cnet,
            Self::Shared(e) => &e.cnet,
            Self::Pyramid(e) => &e.cnet,
        }
    }

    /// How images in 0..255 become the encoders' input (the monocular network of DEFOM-Stereo
    /// reads them so normalised too).
    pub fn normalisation(&self) -> InputNormalisation {
        match self {
            Self::Separate(e) => e.normalisation,
            Self::Shared(_) | Self::Pyramid(_) => InputNormalisation::SignedUnit,
        }
    }

    /// Whether the encoders add a monocular network's features (and so need them).
    pub fn takes_depth_features(&self) -> bool {
        match self {
            Self::Separate(e) => e.fnet.convd.is_some() || e.cnet.conv08.is_some(),
            Self::Shared(_) | Self::Pyramid(_) => false,
        }
    }

    /// The variant's name, as it appears in module paths (`Separate`, `Shared`, `Pyramid`).
    pub fn variant_name(&self) -> &'static str {
        match self {
            Self::Separate(_) => "Separate",
            Self::Shared(_) => "Shared",
            Self::Pyramid(_) => "Pyramid",
        }
    }

    /// Features of both views and the context of `levels` GRU levels, timed on `probe` as the
    /// `feature encoder` and `context encoder` stages.
    ///
    /// The shared backbone runs its trunk on `context_left` and `features_right` (as the
    /// reference, whose trunk sees the image pair once); `features_left` is unused there.
    ///
    /// # Errors
    /// [`Error::Config`] keyed `encoder.depth_features` when the encoders add monocular features
    /// and `inputs.depth` is `None`, or do not and it is given.
    pub fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Result<Encoded> {
        let EncoderInputs { context_left, features_left, features_right, depth } = inputs;
        if depth.is_some() != self.takes_depth_features() {
            let reason = if depth.is_some() {
                "the encoders add no monocular features, but some were given"
            } else {
                "the encoders add monocular features (depth_features = \"added\"), but none were given"
            };
            return Err(Error::config("encoder.depth_features", reason));
        }
        let normalise = |x: Tensor<4>| self.normalisation().apply(x);
        Ok(match self {
            Self::Separate(SeparateEncoders { fnet, cnet, .. }) => {
                let (context_depth, left_depth, right_depth) = match depth {
                    Some(MonocularFeatures { context, left, right, .. }) => (Some(context), Some(left), Some(right)),
                    None => (None, None, None),
                };
                let context = probe.time("context encoder", || {
                    cnet.context_with_depth(normalise(context_left), levels, context_depth.as_deref())
                });
                // One image at a time (the reference batches the pair): the result is the same,
                // as every layer acts per image, and the full-resolution activations of the
                // stem and layer1, the process's peak memory, are half as large.
                let fmap1 =
                    probe.time("feature encoder", || fnet.features_with_depth(normalise(features_left), left_depth));
                let fmap2 =
                    probe.time("feature encoder", || fnet.features_with_depth(normalise(features_right), right_depth));
                Encoded { fmap1, fmap2, context, pyramid: None }
            }
            Self::Shared(SharedBackbone { cnet, conv2 }) => {
                // The trunk sees both images; the context heads only the left.
                let n = context_left.dims()[0];
                // The heads feed only the GRUs, so they take the context encoder's numerics; the
                // trunk feeds `conv2`'s instance norm and keeps the plain products.
                let trunk = probe.time("context encoder", || {
                    cnet.trunk(normalise(Tensor::cat(vec![context_left, features_right], 0)), Numerics::Sensitive)
                });
                let context = probe.time("context encoder", || {
                    cnet.heads(trunk.clone().narrow(0, 0, n), levels, cnet.numerics(), None)
                });
                let feats = probe.time("feature encoder", || conv2.forward(trunk));
                Encoded { fmap1: feats.clone().narrow(0, 0, n), fmap2: feats.narrow(0, n, n), context, pyramid: None }
            }
            Self::Pyramid(PyramidEncoders { feature, stem_2, stem_4, cnet }) => {
                let context = probe.time("context encoder", || cnet.context(normalise(context_left), levels));
                let left = probe
                    .time("feature encoder", || feature_pyramid(feature, [stem_2, stem_4], normalise(features_left)));
                let right = probe
                    .time("feature encoder", || feature_pyramid(feature, [stem_2, stem_4], normalise(features_right)));
                if probe.tracing() {
                    left.record("left", probe);
                    right.record("right", probe);
                }
                let fmap2 = right.levels.into_iter().next().expect("a pyramid has four levels");
                Encoded { fmap1: left.levels[0].clone(), fmap2, context, pyramid: Some(left) }
            }
        })
    }
}
