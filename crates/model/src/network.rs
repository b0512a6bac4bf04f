//! The network: encoders, correlation, iterative updates, upsampling.

use std::collections::BTreeMap;

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::{relu, tanh};
use burn::tensor::{DType, Device, FloatDType, Tensor, TensorData};
use dgstereo_core::DepthPrior;
use dgstereo_core::device::float_dtype;
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_core::tensor::cast_float;
use dgstereo_core::timing::{StageClock, timed};
use dgstereo_costvolume::{CorrelationConfig, CorrelationImplementation, CostVolume};
use dgstereo_encoder::{
    ContextEncoder, ContextExtractor, FeatureEncoder, FeatureExtractor, NormKind, SharedFeatureHead,
};
use dgstereo_fusion::{Fusion, FusionTarget, ImageFusion};
use dgstereo_kernels::{KeptWeights, conv2d_forward};
use dgstereo_updater::{GateContext, GuidanceKind, MultiLevelUpdateBlock, Updater, convex_upsample};

use crate::config::ModelConfig;

/// RAFT-Stereo with the paper's optional depth fusion and GRU guidance.
///
/// Field names follow the official state dict (`fnet`, `cnet`, `conv2`, `context_zqr_convs`,
/// `update_block`), so official checkpoints load by path.
#[derive(Module, Debug)]
pub struct RaftStereo {
    /// Image/depth fusion (identity for RAFT-Stereo).
    pub fusion: Fusion,
    /// Feature encoder (absent with a shared backbone).
    pub fnet: Option<FeatureEncoder>,
    /// Context encoder.
    pub cnet: ContextEncoder,
    /// Feature head of the shared backbone.
    pub conv2: Option<SharedFeatureHead>,
    /// Per level, the 3x3 convolution giving the GRU's context terms `cz, cr, cq`.
    pub context_zqr_convs: Vec<Conv2d>,
    /// The update operator.
    pub update_block: MultiLevelUpdateBlock,
    /// Correlation options.
    #[module(skip)]
    pub correlation: CorrelationConfig,
    /// Guidance options.
    #[module(skip)]
    pub guidance: GuidanceKind,
    /// Whether the fused image feeds the feature encoder too (else the context encoder only).
    #[module(skip)]
    pub fuse_features: bool,
    /// GRU levels in use.
    pub n_gru_layers: usize,
    /// `log2` of the upsampling factor.
    pub n_downsample: usize,
    /// Extra coarse GRU updates per iteration.
    pub slow_fast_gru: bool,
}

/// Named intermediate tensors of one forward pass, for conformance checks.
pub type Trace = BTreeMap<String, Tensor<4>>;

/// Options of [`RaftStereo::forward_flow`] beyond the images, the prior and the iteration count;
/// `ForwardOptions::default()` is inference (last iteration only, configured cost volume).
#[derive(Debug, Default)]
pub struct ForwardOptions<'a> {
    /// Initial x flow at the update grid `[N, 1, H/f, W/f]` (zeros when absent).
    pub flow_init: Option<Tensor<4>>,
    /// Cost volume to use instead of the configured one.
    pub implementation: Option<CorrelationImplementation>,
    /// Upsample and return the flow after every iteration (training), not the last one only.
    pub all_iterations: bool,
    /// Records intermediate tensors under the names of the reference activations
    /// (`fnet.left`, `context.hidden.0`, `iter.3.flow_up`, ...).
    pub trace: Option<&'a mut Trace>,
    /// Times every stage (`feature encoder`, `correlation lookup`, `GRU 1/4`, ...).
    pub clock: Option<&'a mut StageClock>,
}

/// The result of [`RaftStereo::forward_flow`].
#[derive(Debug, Clone)]
pub struct FlowOutput {
    /// Full-resolution x flow (negative disparity) after each iteration kept.
    pub flow_up: Vec<Tensor<4>>,
    /// x flow at the update grid after the last iteration.
    pub flow_lowres: Tensor<4>,
}

impl ModelConfig {
    /// Builds the network with fresh weights, after [`ModelConfig::validate`].
    pub fn init(&self, device: &Device) -> dgstereo_core::Result<RaftStereo> {
        self.validate()?;
        Ok(RaftStereo::new(self, device))
    }
}

impl RaftStereo {
    /// Builds the network with fresh weights (see [`ModelConfig::init`]).
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let u = &config.updater;
        let dims = u.hidden_dims;
        let shared = config.encoder.shared_backbone;
        let trunk = config.encoder.trunk_dims;
        Self {
            fusion: config.fusion.init(device),
            fnet: (!shared).then(|| {
                FeatureEncoder::new(config.encoder.feature_dim, trunk, NormKind::Instance, u.n_downsample, device)
            }),
            cnet: ContextEncoder::new(dims, trunk, config.encoder.context_norm, u.n_downsample, device),
            conv2: shared.then(|| SharedFeatureHead::new(trunk[2], config.encoder.feature_dim, device)),
            context_zqr_convs: (0..u.n_gru_layers)
                .map(|i| conv2d([dims[i], dims[i] * 3], 3, 1, 1, ConvInit::TorchDefault, device))
                .collect(),
            update_block: MultiLevelUpdateBlock::new(u, config.correlation.channels(), device),
            correlation: config.correlation.clone(),
            guidance: u.guidance,
            fuse_features: config.fusion.target() == FusionTarget::Both,
            n_gru_layers: u.n_gru_layers,
            n_downsample: u.n_downsample,
            slow_fast_gru: u.slow_fast_gru,
        }
    }

    /// Runs the network on images already padded to a multiple of `2^(n_downsample+3)`.
    ///
    /// `left`/`right` are RGB in 0..255. Returns the x flow (RAFT-Stereo's sign: negative
    /// disparity) after every iteration with `options.all_iterations`, else after the last one
    /// only; `options` may also trace intermediate tensors and time the stages.
    ///
    /// # Shapes
    /// - `left`, `right`: `[N, 3, H, W]`; prior maps `[N, 1, H, W]`
    /// - `flow_up[k]`: `[N, 1, H, W]`; `flow_lowres`: `[N, 1, H/f, W/f]`
    pub fn forward_flow(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        prior: Option<&DepthPrior>,
        iters: usize,
        options: ForwardOptions<'_>,
    ) -> FlowOutput {
        let ForwardOptions { flow_init, implementation, all_iterations, mut trace, mut clock } = options;
        fn rec(trace: &mut Option<&mut Trace>, name: String, t: &Tensor<4>) {
            if let Some(tr) = trace.as_deref_mut() {
                tr.insert(name, t.clone());
            }
        }
        macro_rules! record {
            ($name:expr, $t:expr) => {
                rec(&mut trace, $name, $t)
            };
        }
        let (prior_left, prior_right) = match prior {
            Some(p) => (Some(p.left.clone()), Some(p.right.clone())),
            None => (None, None),
        };
        let fused_left = timed(&mut clock, "fusion", || self.fusion.fuse(left.clone(), prior_left.clone()));
        let (feat_left, feat_right) = if self.fuse_features {
            (fused_left.clone(), timed(&mut clock, "fusion", || self.fusion.fuse(right.clone(), prior_right)))
        } else {
            (left, right)
        };
        let normalise = |x: Tensor<4>| x.div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0);
        let levels = self.n_gru_layers;

        let (context, fmap1, fmap2) = match (&self.fnet, &self.conv2) {
            (Some(fnet), _) => {
                let context = timed(&mut clock, "context encoder", || self.cnet.context(normalise(fused_left), levels));
                // One image at a time (the reference batches the pair): the result is the same,
                // as every layer acts per image, and the full-resolution activations of the
                // stem and layer1, the process's peak memory, are half as large.
                let f1 = timed(&mut clock, "feature encoder", || fnet.features(normalise(feat_left)));
                let f2 = timed(&mut clock, "feature encoder", || fnet.features(normalise(feat_right)));
                (context, f1, f2)
            }
            (None, Some(head)) => {
                // Shared backbone: the trunk sees both images; the heads only the left.
                let n = feat_left.dims()[0];
                let trunk = timed(&mut clock, "context encoder", || {
                    self.cnet.trunk(normalise(Tensor::cat(vec![fused_left, feat_right], 0)))
                });
                let context =
                    timed(&mut clock, "context encoder", || self.cnet.heads(trunk.clone().narrow(0, 0, n), levels));
                let feats = timed(&mut clock, "feature encoder", || head.forward(trunk));
                (context, feats.clone().narrow(0, 0, n), feats.narrow(0, n, n))
            }
            (None, None) => unreachable!("a network has either fnet or conv2"),
        };
        record!("fnet.left".into(), &fmap1);
        record!("fnet.right".into(), &fmap2);

        let mut hidden: Vec<Tensor<4>> = Vec::with_capacity(levels);
        let mut gates: Vec<GateContext> = Vec::with_capacity(levels);
        for (i, [h, c]) in context.levels.into_iter().enumerate() {
            let (h, g) = timed(&mut clock, "context encoder", || {
                (tanh(h), GateContext::from_zqr(conv2d_forward(&self.context_zqr_convs[i], relu(c))))
            });
            record!(format!("context.hidden.{i}"), &h);
            record!(format!("context.z.{i}"), &g.z);
            record!(format!("context.r.{i}"), &g.r);
            record!(format!("context.q.{i}"), &g.q);
            hidden.push(h);
            gates.push(g);
        }

        // In half precision the correlation, its lookup, the match positions and the upsampling
        // stay in f32, as in the reference's mixed precision (its `fmap1.float()` before the
        // volume, its lookup and `coords1 + delta_flow` outside `autocast`): a half-precision
        // position has a spacing of 1/4 pixel beyond 256, which the lookup's interpolation
        // weights would inherit. The encoders and the update block run in the device's dtype.
        let dtype = float_dtype(&fmap1.device());
        let (fmap1, fmap2) = (cast_float(fmap1, FloatDType::F32), cast_float(fmap2, FloatDType::F32));
        let implementation = implementation.unwrap_or(self.correlation.implementation);
        let corr_fn =
            timed(&mut clock, "correlation build", || self.correlation.build_with(implementation, fmap1, fmap2));
        if let (Some(tr), dgstereo_costvolume::Correlation::Reg(p)) = (trace.as_deref_mut(), &corr_fn) {
            for (i, level) in p.levels().iter().enumerate() {
                let [m, w] = level.dims();
                tr.insert(format!("corr.pyramid.{i}"), level.clone().reshape([m, 1, 1, w]));
            }
        }

        let [n, _, h, w] = hidden[0].dims();
        let device = hidden[0].device();
        let grid = [h, w];
        let guidance =
            timed(&mut clock, "guidance", || prior.and_then(|p| self.guidance.feature(p.left.clone(), grid)));
        let f32_on = (&device, DType::F32);
        let coords0 =
            Tensor::<1>::from_data(TensorData::new((0..w).map(|x| x as f32).collect::<Vec<_>>(), [w]), f32_on)
                .reshape([1, 1, 1, w])
                .expand([n, 1, h, w]);
        let mut flow_x = match flow_init {
            Some(flow) => cast_float(flow, FloatDType::F32),
            None => Tensor::zeros([n, 1, h, w], f32_on),
        };
        let zeros = Tensor::<4>::zeros([n, 1, h, w], &device);
        let factor = 1usize << self.n_downsample;
        let mut flow_up = Vec::new();
        // The iterations run the same convolutions: their transformed weights are kept until the
        // loop ends (host Winograd path only; results unchanged).
        let _kept = KeptWeights::new();
        for k in 0..iters {
            flow_x = flow_x.detach();
            let corr = timed(&mut clock, "correlation lookup", || {
                cast_float(corr_fn.lookup(coords0.clone() + flow_x.clone()), dtype)
            });
            record!(format!("iter.{k}.corr"), &corr);
            if self.slow_fast_gru {
                if levels == 3 {
                    self.update_block.update_coarse(&mut hidden, &gates, true, false, &mut clock);
                }
                if levels >= 2 {
                    self.update_block.update_coarse(&mut hidden, &gates, levels == 3, true, &mut clock);
                }
            }
            let flow = Tensor::cat(vec![cast_float(flow_x.clone(), dtype), zeros.clone()], 1);
            let out = self.update_block.step(&mut hidden, &gates, corr, flow, guidance.as_ref(), clock.as_deref_mut());
            flow_x = flow_x + cast_float(out.delta_x, FloatDType::F32);
            for (i, hi) in hidden.iter().enumerate() {
                record!(format!("iter.{k}.hidden.{i}"), hi);
            }
            record!(format!("iter.{k}.flow_lowres"), &flow_x);
            // The mask never feeds back into the state: computed only where it is used.
            let upsampled = all_iterations || k + 1 == iters;
            if upsampled || trace.is_some() {
                let up_mask = timed(&mut clock, "mask head", || Updater::upsample_mask(&self.update_block, &hidden));
                record!(format!("iter.{k}.up_mask"), &up_mask);
                if !upsampled {
                    continue;
                }
                let up = timed(&mut clock, "convex upsample", || {
                    convex_upsample(flow_x.clone(), cast_float(up_mask, FloatDType::F32), factor)
                });
                record!(format!("iter.{k}.flow_up"), &up);
                flow_up.push(up);
            }
        }
        FlowOutput { flow_up, flow_lowres: flow_x }
    }
}
