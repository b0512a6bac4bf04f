//! The encoder layouts: separate feature and context encoders, or a shared backbone.

use burn::module::Module;
use burn::tensor::Tensor;
use dgstereo_core::Probe;
use dgstereo_kernels::Numerics;

use crate::context::ContextEncoder;
use crate::feature::{FeatureEncoder, SharedFeatureHead};
use crate::{ContextExtractor, ContextFeatures, FeatureExtractor};

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
}

/// RAFT-Stereo's two encoders, each with its own trunk (the reference's `fnet` and `cnet`).
#[derive(Module, Debug)]
pub struct SeparateEncoders {
    /// Feature encoder.
    pub fnet: FeatureEncoder,
    /// Context encoder.
    pub cnet: ContextEncoder,
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

/// A built encoder layout, chosen by [`EncoderConfig`](crate::EncoderConfig).
// One per network, its variants' sizes are the modules' own: boxing them would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Encoders {
    /// Separate feature and context encoders.
    Separate(SeparateEncoders),
    /// One trunk for both.
    Shared(SharedBackbone),
}

/// `x / 255 * 2 - 1`: the encoders' input range.
fn normalise(x: Tensor<4>) -> Tensor<4> {
    x.div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0)
}

impl Encoders {
    /// The context encoder (either layout has one).
    pub fn context_encoder(&self) -> &ContextEncoder {
        match self {
            Self::Separate(e) => &e.cnet,
            Self::Shared(e) => &e.cnet,
        }
    }

    /// The variant's name, as it appears in module paths (`Separate`, `Shared`).
    pub fn variant_name(&self) -> &'static str {
        match self {
            Self::Separate(_) => "Separate",
            Self::Shared(_) => "Shared",
        }
    }

    /// Features of both views and the context of `levels` GRU levels, timed on `probe` as the
    /// `feature encoder` and `context encoder` stages.
    ///
    /// The shared backbone runs its trunk on `context_left` and `features_right` (as the
    /// reference, whose trunk sees the image pair once); `features_left` is unused there.
    pub fn encode(&self, inputs: EncoderInputs, levels: usize, probe: &mut Probe<'_>) -> Encoded {
        let EncoderInputs { context_left, features_left, features_right } = inputs;
        match self {
            Self::Separate(SeparateEncoders { fnet, cnet }) => {
                let context = probe.time("context encoder", || cnet.context(normalise(context_left), levels));
                // One image at a time (the reference batches the pair): the result is the same,
                // as every layer acts per image, and the full-resolution activations of the
                // stem and layer1, the process's peak memory, are half as large.
                let fmap1 = probe.time("feature encoder", || fnet.features(normalise(features_left)));
                let fmap2 = probe.time("feature encoder", || fnet.features(normalise(features_right)));
                Encoded { fmap1, fmap2, context }
            }
            Self::Shared(SharedBackbone { cnet, conv2 }) => {
                // The trunk sees both images; the context heads only the left.
                let n = context_left.dims()[0];
                // The heads feed only the GRUs, so they take the context encoder's numerics; the
                // trunk feeds `conv2`'s instance norm and keeps the plain products.
                let trunk = probe.time("context encoder", || {
                    cnet.trunk(normalise(Tensor::cat(vec![context_left, features_right], 0)), Numerics::Sensitive)
                });
                let context = probe
                    .time("context encoder", || cnet.heads(trunk.clone().narrow(0, 0, n), levels, cnet.numerics()));
                let feats = probe.time("feature encoder", || conv2.forward(trunk));
                Encoded { fmap1: feats.clone().narrow(0, 0, n), fmap2: feats.narrow(0, n, n), context }
            }
        }
    }
}
