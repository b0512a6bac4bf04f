//! The network: encoders, correlation, iterative updates, upsampling.
//!
//! Each stage owns its variants: the fusion, the encoder layout, the cost volume and the update
//! schedule are chosen in their crates' configs and built there, so the forward pass below only
//! wires them in RAFT-Stereo's order. It reports intermediate tensors and stage times through
//! one [`Probe`].
//!
//! The pass is written once, as stage functions that [`RaftStereo::forward_flow`] calls in
//! sequence: `encode` (fusion, encoders, the GRUs' initial states and context), then
//! `correlation_volume` and `update_grid` once, per iteration `lookup` and `update`, and
//! `upsample_weights` with `upsample` where a flow is returned. The per-stage backward profile
//! ([`crate::stage_backward`]) runs the same functions, one stage at a time.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::{relu, tanh};
use burn::tensor::{DType, Device, FloatDType, Tensor, TensorData};
use dgstereo_core::DepthPrior;
use dgstereo_core::device::float_dtype;
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_core::tensor::cast_float;
use dgstereo_costvolume::{Correlation, CorrelationConfig, CorrelationImplementation, CostVolume};
use dgstereo_encoder::{ContextFeatures, Encoded, EncoderInputs, Encoders};
use dgstereo_fusion::{Fusion, FusionTarget, ImageFusion};
use dgstereo_kernels::{Numerics, UpdateLoop, conv2d_forward};
use dgstereo_updater::{GateContext, GuidanceKind, MultiLevelUpdateBlock, Updater, convex_upsample};

use crate::config::ModelConfig;

pub use dgstereo_core::{Probe, Trace};

/// RAFT-Stereo with the paper's optional depth fusion and GRU guidance.
///
/// Field names follow the official state dict (`context_zqr_convs`, `update_block`; the encoder
/// layout holds `fnet`, `cnet` and `conv2`), so official checkpoints load by path.
#[derive(Module, Debug)]
pub struct RaftStereo {
    /// Image/depth fusion (identity for RAFT-Stereo).
    pub fusion: Fusion,
    /// Feature and context encoders, separate or with a shared backbone.
    pub encoder: Encoders,
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
}

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
    /// Where intermediate tensors are recorded, under the names of the reference activations
    /// (`fnet.left`, `context.hidden.0`, `iter.3.flow_up`, ...), and stages timed
    /// (`feature encoder`, `correlation lookup`, `GRU 1/4`, ...); [`Probe::none`] by default.
    pub probe: Probe<'a>,
}

/// What the encoders give the update loop ([`RaftStereo::encode`]).
#[derive(Debug)]
pub(crate) struct Encodings {
    /// Left features `[N, C, H/f, W/f]`.
    pub fmap1: Tensor<4>,
    /// Right features, as `fmap1`.
    pub fmap2: Tensor<4>,
    /// Per GRU level, finest first, the initial hidden state.
    pub hidden: Vec<Tensor<4>>,
    /// Per GRU level, finest first, the gates' context terms.
    pub gates: Vec<GateContext>,
}

/// The fixed inputs of the update loop at the update grid `[N, 1, H/f, W/f]`
/// ([`RaftStereo::update_grid`]).
#[derive(Debug)]
pub(crate) struct UpdateGrid {
    /// Each pixel's own x position (f32): the match of a zero flow.
    coords0: Tensor<4>,
    /// The y flow, zero (RAFT-Stereo's update block reads a two-channel flow).
    zeros: Tensor<4>,
    /// The GRU's guidance feature (`None` without guidance or prior).
    guidance: Option<Tensor<4>>,
    /// The update block's dtype (the device's).
    dtype: FloatDType,
}

impl UpdateGrid {
    /// A zero x flow (f32), the loop's start without an initial flow.
    pub(crate) fn zero_flow(&self) -> Tensor<4> {
        Tensor::zeros(self.coords0.dims(), (&self.coords0.device(), DType::F32))
    }
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
        RaftStereo::new(self, device)
    }
}

impl RaftStereo {
    /// Builds the network with fresh weights (see [`ModelConfig::init`]).
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] when a stage refuses its configuration.
    pub fn new(config: &ModelConfig, device: &Device) -> dgstereo_core::Result<Self> {
        let u = &config.updater;
        let dims = u.hidden_dims;
        Ok(Self {
            fusion: config.fusion.init(device)?,
            encoder: config.encoder.init(dims, u.n_downsample, device),
            // Level `i` counts from the finest (1/4, `hidden_dims[2]`) as the context does.
            context_zqr_convs: (0..u.n_gru_layers)
                .map(|i| {
                    let d = dims[2 - i];
                    conv2d([d, d * 3], 3, 1, 1, ConvInit::TorchDefault, device)
                })
                .collect(),
            update_block: MultiLevelUpdateBlock::new(u, config.correlation.channels(), device),
            correlation: config.correlation.clone(),
            guidance: u.guidance,
            fuse_features: config.fusion.target() == FusionTarget::Both,
            n_gru_layers: u.n_gru_layers,
            n_downsample: u.n_downsample,
        })
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
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] when the fusion or the guidance needs the depth prior and
    /// `prior` is `None` (the checked entry points answer this first with [`ModelConfig::check_prior`]).
    pub fn forward_flow(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        prior: Option<&DepthPrior>,
        iters: usize,
        options: ForwardOptions<'_>,
    ) -> dgstereo_core::Result<FlowOutput> {
        let ForwardOptions { flow_init, implementation, all_iterations, mut probe } = options;
        let probe = &mut probe;
        let Encodings { fmap1, fmap2, mut hidden, gates } = self.encode(left, right, prior, probe)?;
        let implementation = implementation.unwrap_or(self.correlation.implementation);
        let corr_fn = self.correlation_volume(fmap1, fmap2, implementation, probe);
        let grid = self.update_grid(&hidden[0], prior, probe)?;
        let mut flow_x = match flow_init {
            Some(flow) => cast_float(flow, FloatDType::F32),
            None => grid.zero_flow(),
        };
        let mut flow_up = Vec::new();
        // The iterations run the same convolutions: their transformed weights are kept until the
        // loop ends, and the training forward takes Winograd in it (see `UpdateLoop`).
        let _update_loop = UpdateLoop::new();
        for k in 0..iters {
            flow_x = flow_x.detach();
            let corr = self.lookup(&corr_fn, &grid, flow_x.clone(), probe);
            probe.record(format_args!("iter.{k}.corr"), &corr);
            let delta_x = self.update(&mut hidden, &gates, corr, &grid, flow_x.clone(), probe);
            flow_x = flow_x + cast_float(delta_x, FloatDType::F32);
            for (i, hi) in hidden.iter().enumerate() {
                probe.record(format_args!("iter.{k}.hidden.{i}"), hi);
            }
            probe.record(format_args!("iter.{k}.flow_lowres"), &flow_x);
            // The mask never feeds back into the state: computed only where it is used.
            let upsampled = all_iterations || k + 1 == iters;
            if upsampled || probe.tracing() {
                let up_mask = self.upsample_weights(&hidden, probe);
                probe.record(format_args!("iter.{k}.up_mask"), &up_mask);
                if !upsampled {
                    continue;
                }
                let up = self.upsample(flow_x.clone(), up_mask, probe);
                probe.record(format_args!("iter.{k}.flow_up"), &up);
                flow_up.push(up);
            }
        }
        Ok(FlowOutput { flow_up, flow_lowres: flow_x })
    }

    /// Stage 1, fusion and encoders: both views' features, and per GRU level the initial hidden
    /// state and the gates' context terms.
    pub(crate) fn encode(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        prior: Option<&DepthPrior>,
        probe: &mut Probe<'_>,
    ) -> dgstereo_core::Result<Encodings> {
        let Encoded { fmap1, fmap2, context } =
            self.encoder.encode(self.fuse(left, right, prior, probe)?, self.n_gru_layers, probe);
        probe.record("fnet.left", &fmap1);
        probe.record("fnet.right", &fmap2);
        let (hidden, gates) = self.gru_context(context, probe);
        Ok(Encodings { fmap1, fmap2, hidden, gates })
    }

    /// Stage 2, the cost volume of `fmap1` against `fmap2` (`[N, C, H/f, W/f]`) by
    /// `implementation`, built once per pass.
    ///
    /// In half precision the correlation, its lookup, the match positions and the upsampling stay
    /// in f32, as in the reference's mixed precision (its `fmap1.float()` before the volume, its
    /// lookup and `coords1 + delta_flow` outside `autocast`): a half-precision position has a
    /// spacing of 1/4 pixel beyond 256, which the lookup's interpolation weights would inherit.
    /// The encoders and the update block run in the device's dtype.
    pub(crate) fn correlation_volume(
        &self,
        fmap1: Tensor<4>,
        fmap2: Tensor<4>,
        implementation: CorrelationImplementation,
        probe: &mut Probe<'_>,
    ) -> Correlation {
        let (fmap1, fmap2) = (cast_float(fmap1, FloatDType::F32), cast_float(fmap2, FloatDType::F32));
        let corr_fn = probe.time("correlation build", || self.correlation.build_with(implementation, fmap1, fmap2));
        if let (true, Correlation::Reg(p)) = (probe.tracing(), &corr_fn) {
            for (i, level) in p.levels().iter().enumerate() {
                let [m, w] = level.dims();
                // A level pooled below one column (narrow inputs) holds nothing to record, and
                // burn cannot reshape an empty tensor on the capture device.
                if m * w > 0 {
                    probe.record(format_args!("corr.pyramid.{i}"), &level.clone().reshape([m, 1, 1, w]));
                }
            }
        }
        corr_fn
    }

    /// The update loop's fixed inputs at the grid of the finest hidden state `hidden_fine`
    /// (`[N, C, H/f, W/f]`): the positions, the zero y flow and the guidance feature from the left
    /// prior (computed once per pass).
    pub(crate) fn update_grid(
        &self,
        hidden_fine: &Tensor<4>,
        prior: Option<&DepthPrior>,
        probe: &mut Probe<'_>,
    ) -> dgstereo_core::Result<UpdateGrid> {
        let [n, _, h, w] = hidden_fine.dims();
        let device = hidden_fine.device();
        if prior.is_none() && self.guidance != GuidanceKind::None {
            // As the fusion refuses to run without its prior: the motion encoder's guidance
            // branch would otherwise see no input.
            return Err(dgstereo_core::Error::config(
                "updater.guidance",
                format!("{} guidance needs the depth prior, and none was given", self.guidance.name()),
            ));
        }
        let guidance = probe.time("guidance", || prior.and_then(|p| self.guidance.feature(p.left.clone(), [h, w])));
        let f32_on = (&device, DType::F32);
        let coords0 =
            Tensor::<1>::from_data(TensorData::new((0..w).map(|x| x as f32).collect::<Vec<_>>(), [w]), f32_on)
                .reshape([1, 1, 1, w])
                .expand([n, 1, h, w]);
        let zeros = Tensor::<4>::zeros([n, 1, h, w], &device);
        Ok(UpdateGrid { coords0, zeros, guidance, dtype: float_dtype(&device) })
    }

    /// Stage 3, one iteration's lookup: the cost volume sampled around each pixel's match at
    /// `x + flow_x` (`flow_x`: `[N, 1, H/f, W/f]`, f32), in the update block's dtype.
    pub(crate) fn lookup(
        &self,
        corr_fn: &Correlation,
        grid: &UpdateGrid,
        flow_x: Tensor<4>,
        probe: &mut Probe<'_>,
    ) -> Tensor<4> {
        probe.time("correlation lookup", || cast_float(corr_fn.lookup(grid.coords0.clone() + flow_x), grid.dtype))
    }

    /// Stage 4, one update step: advances `hidden` from the lookup `corr` and the current
    /// `flow_x` (f32) and returns the x flow's update, in the update block's dtype.
    pub(crate) fn update(
        &self,
        hidden: &mut [Tensor<4>],
        gates: &[GateContext],
        corr: Tensor<4>,
        grid: &UpdateGrid,
        flow_x: Tensor<4>,
        probe: &mut Probe<'_>,
    ) -> Tensor<4> {
        let flow = Tensor::cat(vec![cast_float(flow_x, grid.dtype), grid.zeros.clone()], 1);
        self.update_block.step(hidden, gates, corr, flow, grid.guidance.as_ref(), probe).delta_x
    }

    /// Stage 5a, the mask head: the convex upsampling's weights from the finest state.
    pub(crate) fn upsample_weights(&self, hidden: &[Tensor<4>], probe: &mut Probe<'_>) -> Tensor<4> {
        probe.time("mask head", || self.update_block.upsample_mask(hidden))
    }

    /// Stage 5b, convex upsampling of `flow_x` (f32) to full resolution by `mask`.
    pub(crate) fn upsample(&self, flow_x: Tensor<4>, mask: Tensor<4>, probe: &mut Probe<'_>) -> Tensor<4> {
        let factor = 1usize << self.n_downsample;
        probe.time("convex upsample", || convex_upsample(flow_x, cast_float(mask, FloatDType::F32), factor))
    }

    /// The images each encoder sees: the fused left view for the context, and for the features
    /// the fused views or the raw ones ([`FusionTarget`]); an error when the fusion needs the
    /// prior and there is none.
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
        Ok(EncoderInputs { context_left, features_left, features_right })
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
