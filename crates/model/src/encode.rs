//! Stage 1 of the forward pass: the monocular network, the fusion, the encoders, the GRUs'
//! context and the initial disparity.
//!
//! The monocular network (DEFOM-Stereo's Depth Anything V2) runs first, on both views normalised
//! as the encoders see them; its features go to the encoders that add them, its inverse depth to
//! the disparity initialiser ([`crate::initial_disparity`]).

use burn::tensor::FloatDType;
use burn::tensor::Tensor;
use burn::tensor::activation::{relu, tanh};
use dgstereo_core::tensor::cast_float;
use dgstereo_core::{DepthPrior, MonocularFeatures, Probe};
use dgstereo_encoder::{ContextFeatures, Encoded, EncoderInputs, StereoEncoder};
use dgstereo_fusion::ImageFusion;
use dgstereo_kernels::{Numerics, conv2d_forward};
use dgstereo_updater::GateContext;

use crate::RaftStereo;
use crate::network::{Encodings, state_of_flow};

impl RaftStereo {
    /// Stage 1, monocular network, fusion and encoders: both views' features, per GRU level the
    /// initial hidden state and the gates' context terms, and the initial state of the loop
    /// where the initialiser gives one.
    pub(crate) fn encode(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        prior: Option<&DepthPrior>,
        probe: &mut Probe<'_>,
    ) -> dgstereo_core::Result<Encodings> {
        let monocular = self.monocular_features(left.clone(), right.clone(), probe);
        // The soft-argmin reads the geometry volume, which the geometry stage builds after this.
        let initial = match self.initial_disparity.needs_geometry() {
            true => None,
            false => self.initial_disparity.disparity(monocular.as_ref(), None)?,
        };
        if let Some(d) = &initial {
            probe.record("initial_disparity", d);
        }
        let mut inputs = self.fuse(left, right, prior, probe)?;
        // Only encoders that add the features get them (the initialiser may be their only reader).
        inputs.depth = monocular.filter(|_| self.encoder.takes_depth_features());
        let Encoded { fmap1, fmap2, context, pyramid } = self.encoder.encode(inputs, self.n_gru_layers, probe)?;
        probe.record("fnet.left", &fmap1);
        probe.record("fnet.right", &fmap2);
        let (hidden, gates) = self.gru_context(context, probe);
        // The loop's state of the x flow `-d`.
        let initial = initial.map(|d| state_of_flow(self.motion, cast_float(d, FloatDType::F32).neg()));
        Ok(Encodings { fmap1, fmap2, hidden, gates, initial, pyramid })
    }

    /// The monocular network's features of both views (normalised as the encoders see them),
    /// `None` without one.
    fn monocular_features(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        probe: &mut Probe<'_>,
    ) -> Option<MonocularFeatures> {
        let network = self.monocular.as_ref()?;
        let normalisation = self.encoder.normalisation();
        let features = probe.time("monocular network", || {
            network.features(normalisation.apply(left), normalisation.apply(right), self.n_downsample)
        });
        if probe.tracing() {
            for (i, c) in features.context.iter().enumerate() {
                probe.record(format_args!("monocular.context.{i}"), c);
            }
            probe.record("monocular.left", &features.left);
            probe.record("monocular.right", &features.right);
            probe.record("monocular.inverse_depth", &features.inverse_depth);
        }
        Some(features)
    }

    /// The images each encoder sees: the fused left view for the context, and for the features
    /// the fused views or the raw ones ([`dgstereo_fusion::FusionTarget`]); an error when the
    /// fusion needs the prior and there is none.
    pub(crate) fn fuse(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        prior: Option<&DepthPrior>,
        probe: &mut Probe<'_>,
    ) -> dgstereo_core::Result<EncoderInputs> {
        let (prior_left, prior_right) = match prior {
            Some(p) => (Some(p.left.clone()), Some(p.right.clone())),
            None => (None, None),
        };
        let context_left = probe.time("fusion", || self.fusion.fuse(left.clone(), prior_left))?;
        let (features_left, features_right) = if self.fuse_features {
            (context_left.clone(), probe.time("fusion", || self.fusion.fuse(right, prior_right))?)
        } else {
            (left, right)
        };
        Ok(EncoderInputs { context_left, features_left, features_right, depth: None })
    }

    /// The GRUs' initial hidden states (tanh of the first heads) and their gate context terms
    /// (the `context_zqr_convs` of the ReLU of the second heads), finest level first.
    pub(crate) fn gru_context(
        &self,
        context: ContextFeatures,
        probe: &mut Probe<'_>,
    ) -> (Vec<Tensor<4>>, Vec<GateContext>) {
        let levels = context.levels.len();
        let mut hidden: Vec<Tensor<4>> = Vec::with_capacity(levels);
        let mut gates: Vec<GateContext> = Vec::with_capacity(levels);
        for (i, [h, c]) in context.levels.into_iter().enumerate() {
            if probe.tracing() {
                probe.record(format_args!("cnet.{i}.0"), &h);
                probe.record(format_args!("cnet.{i}.1"), &c);
            }
            let (h, g) = probe.time("context encoder", || {
                (
                    tanh(h),
                    GateContext::from_zqr(conv2d_forward(&self.context_zqr_convs[i], relu(c), Numerics::Sensitive)),
                )
            });
            probe.record(format_args!("context.hidden.{i}"), &h);
            probe.record(format_args!("context.z.{i}"), &g.z);
            probe.record(format_args!("context.r.{i}"), &g.r);
            probe.record(format_args!("context.q.{i}"), &g.q);
            hidden.push(h);
            gates.push(g);
        }
        (hidden, gates)
    }
}
