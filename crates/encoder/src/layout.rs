//! The encoder layouts: separate feature and context encoders, a shared backbone, or
//! IGEV-Stereo's feature pyramid beside the context encoder. Each implements [`StereoEncoder`];
//! [`Encoders`] is the one a configuration built, and delegates with one `match`.

use burn::module::Module;
use burn::tensor::Tensor;
use dgstereo_core::conv_blocks::InstanceStem;
use dgstereo_core::{Error, MonocularFeatures, Probe, Result};
use dgstereo_kernels::Numerics;

use crate::context::ContextEncoder;
use crate::depth_block::InputNormalisation;
use crate::feature::{FeatureEncoder, SharedFeatureHead};
use crate::pyramid::{FeaturePyramid, MobileNetPyramid, feature_pyramid};
use crate::{ContextFeatures, StereoEncoder};

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
    /// The context encoder (every layout has one).
    pub fn context_encoder(&self) -> &ContextEncoder {
        match self {
            Self::Separate(e) => &e.cnet,
            Self::Shared(e) => &e.cnet,
            Self::Pyramid(e) => &e.cnet,
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

    /// The layout as the trait object the variant is.
    fn layout(&self) -> &dyn StereoEncoder {
        match self {
            Self::Separate(e) => e,
            Self::Shared(e) => e,
            Self::Pyramid(e) => e,
        }
    }
}

impl StereoEncoder for Encoders {
    fn normalisation(&self) -> InputNormalisation {
        self.layout().normalisation()
    }

    fn takes_depth_features(&self) -> bool {
        self.layout().takes_depth_features()
    }

    fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Result<Encoded> {
        self.layout().encode(inputs, levels, probe)
    }
}

/// Refuses monocular features given to a layout that does not add them, or missing where it
/// does.
fn check_depth(layout: &dyn StereoEncoder, depth: &Option<MonocularFeatures>) -> Result<()> {
    if depth.is_some() == layout.takes_depth_features() {
        return Ok(());
    }
    let reason = if depth.is_some() {
        "the encoders add no monocular features, but some were given"
    } else {
        "the encoders add monocular features (depth_features = \"added\"), but none were given"
    };
    Err(Error::config("encoder.depth_features", reason))
}

impl StereoEncoder for SeparateEncoders {
    fn normalisation(&self) -> InputNormalisation {
        self.normalisation
    }

    fn takes_depth_features(&self) -> bool {
        self.fnet.convd.is_some() || self.cnet.conv08.is_some()
    }

    fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Result<Encoded> {
        check_depth(self, &inputs.depth)?;
        let EncoderInputs { context_left, features_left, features_right, depth } = inputs;
        let normalise = |x: Tensor<4>| self.normalisation.apply(x);
        let (context_depth, left_depth, right_depth) = match depth {
            Some(MonocularFeatures { context, left, right, .. }) => (Some(context), Some(left), Some(right)),
            None => (None, None, None),
        };
        let context = probe.time("context encoder", || {
            self.cnet.context_with_depth(normalise(context_left), levels, context_depth.as_deref())
        });
        // One image at a time (the reference batches the pair): the result is the same, as every
        // layer acts per image, and the full-resolution activations of the stem and layer1, the
        // process's peak memory, are half as large.
        let fnet = &self.fnet;
        let fmap1 = probe.time("feature encoder", || fnet.features_with_depth(normalise(features_left), left_depth));
        let fmap2 = probe.time("feature encoder", || fnet.features_with_depth(normalise(features_right), right_depth));
        Ok(Encoded { fmap1, fmap2, context, pyramid: None })
    }
}

impl StereoEncoder for SharedBackbone {
    fn normalisation(&self) -> InputNormalisation {
        InputNormalisation::SignedUnit
    }

    fn takes_depth_features(&self) -> bool {
        false
    }

    /// The trunk runs on `context_left` and `features_right` (as the reference, whose trunk sees
    /// the image pair once); `features_left` is unused.
    fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Result<Encoded> {
        check_depth(self, &inputs.depth)?;
        let EncoderInputs { context_left, features_right, .. } = inputs;
        let Self { cnet, conv2 } = self;
        let normalise = |x: Tensor<4>| self.normalisation().apply(x);
        // The trunk sees both images; the context heads only the left.
        let n = context_left.dims()[0];
        // The heads feed only the GRUs, so they take the context encoder's numerics; the trunk
        // feeds `conv2`'s instance norm and keeps the plain products.
        let trunk = probe.time("context encoder", || {
            cnet.trunk(normalise(Tensor::cat(vec![context_left, features_right], 0)), Numerics::Sensitive)
        });
        let context =
            probe.time("context encoder", || cnet.heads(trunk.clone().narrow(0, 0, n), levels, cnet.numerics(), None));
        let feats = probe.time("feature encoder", || conv2.forward(trunk));
        Ok(Encoded { fmap1: feats.clone().narrow(0, 0, n), fmap2: feats.narrow(0, n, n), context, pyramid: None })
    }
}

impl StereoEncoder for PyramidEncoders {
    fn normalisation(&self) -> InputNormalisation {
        InputNormalisation::SignedUnit
    }

    fn takes_depth_features(&self) -> bool {
        false
    }

    fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Result<Encoded> {
        check_depth(self, &inputs.depth)?;
        let EncoderInputs { context_left, features_left, features_right, .. } = inputs;
        let Self { feature, stem_2, stem_4, cnet } = self;
        let normalise = |x: Tensor<4>| self.normalisation().apply(x);
        let context = probe.time("context encoder", || cnet.context(normalise(context_left), levels));
        let left =
            probe.time("feature encoder", || feature_pyramid(feature, [stem_2, stem_4], normalise(features_left)));
        let right =
            probe.time("feature encoder", || feature_pyramid(feature, [stem_2, stem_4], normalise(features_right)));
        if probe.tracing() {
            left.record("left", probe);
            right.record("right", probe);
        }
        let fmap2 = right.levels.into_iter().next().expect("a pyramid has four levels");
        Ok(Encoded { fmap1: left.levels[0].clone(), fmap2, context, pyramid: Some(left) })
    }
}
