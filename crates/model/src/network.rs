//! The network: encoders, correlation, iterative updates, upsampling.
//!
//! Each stage owns its variants: the fusion, the encoder layout, the cost volume and the update
//! schedule are chosen in their crates' configs and built there, so the forward pass below only
//! wires them in RAFT-Stereo's order. It reports intermediate tensors and stage times through
//! one [`Probe`].
//!
//! The pass is written once, as stage functions that [`RaftStereo::forward_flow`] calls in
//! sequence: `encode` (monocular network, fusion, encoders, the GRUs' initial states and context,
//! the initial disparity; the `encode` module), then `correlation_volume` and `update_grid` once,
//! per iteration `lookup` (or `scale_lookup`) and `update`, and `upsample_weights` with
//! `upsample` where a flow is returned. The per-stage backward profile
//! ([`crate::stage_backward`]) runs the same functions, one stage at a time.
//!
//! DEFOM-Stereo is this pass with its variants chosen: the loop's state is then a positive
//! disparity ([`MotionKind::Disparity`], looked up at `x - d`) rather than RAFT-Stereo's x flow
//! (at `x + f`), it starts from the initialiser's disparity, and its first `scale_iters`
//! iterations run the scale block on the scale lookup and multiply the disparity. What the
//! pass returns is the x flow either way.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::softmax;
use burn::tensor::{DType, Device, FloatDType, Tensor, TensorData};
use dgstereo_core::device::float_dtype;
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_core::tensor::cast_float;
use dgstereo_core::{DepthPrior, Error};
use dgstereo_costvolume::{Correlation, CorrelationConfig, CorrelationImplementation, CostVolume, GeometryEncoding};
use dgstereo_encoder::{Encoders, FeaturePyramid};
use dgstereo_fusion::{Fusion, FusionTarget};
use dgstereo_kernels::UpdateLoop;
use dgstereo_prior::DepthAnythingV2Features;
use dgstereo_updater::{
    GateContext, GuidanceKind, HeadOutput, MotionKind, MultiLevelUpdateBlock, SuperpixelUpsampler, UpdateOutput,
    UpsamplingKind, context_upsample, convex_upsample,
};

use crate::config::ModelConfig;
use crate::initial_disparity::InitialDisparity;

pub use dgstereo_core::{Probe, Trace};

/// RAFT-Stereo with the paper's optional depth fusion and GRU guidance, and DEFOM-Stereo's
/// variants.
///
/// Field names follow the official state dicts (`context_zqr_convs`, `update_block`,
/// `scale_update_block`; the encoder layout holds `fnet`, `cnet` and `conv2`), so official
/// checkpoints load by path; DEFOM-Stereo's `defomencoder.depth_anything` is `monocular`.
#[derive(Module, Debug)]
pub struct RaftStereo {
    /// The monocular network inside the stereo network (DEFOM-Stereo), none in RAFT-Stereo.
    pub monocular: Option<DepthAnythingV2Features>,
    /// Image/depth fusion (identity for RAFT-Stereo).
    pub fusion: Fusion,
    /// Feature and context encoders, separate or with a shared backbone.
    pub encoder: Encoders,
    /// IGEV-Stereo's geometry encoding volume (the reference's top-level `conv`, `desc`,
    /// `corr_stem`, `corr_feature_att`, `cost_agg`, `classifier`); none in RAFT-Stereo.
    pub geometry: Option<GeometryEncoding>,
    /// Per level, the 3x3 convolution giving the GRU's context terms `cz, cr, cq`.
    pub context_zqr_convs: Vec<Conv2d>,
    /// The update operator.
    pub update_block: MultiLevelUpdateBlock,
    /// IGEV-Stereo's superpixel upsampling heads (the reference's top-level `spx*`); none with
    /// convex upsampling.
    pub superpixel: Option<SuperpixelUpsampler>,
    /// The scale update operator run for the first `scale_iters` iterations (DEFOM-Stereo).
    pub scale_update_block: Option<MultiLevelUpdateBlock>,
    /// Iterations that run the scale update block.
    pub scale_iters: usize,
    /// What the loop iterates: RAFT-Stereo's x flow or a positive disparity.
    #[module(skip)]
    pub motion: MotionKind,
    /// Where the loop starts.
    #[module(skip)]
    pub initial_disparity: InitialDisparity,
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
    /// Also return the loop's start upsampled by the network's own weights (training, for a
    /// loss on it: IGEV-Stereo's soft-argmin start through its initial superpixel heads).
    pub upsample_initial: bool,
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
    /// The loop's initial state (f32, the motion's convention) where the initialiser gives
    /// one; zero otherwise (and for the soft-argmin, which the geometry stage computes).
    pub initial: Option<Tensor<4>>,
    /// The left view's feature pyramid and 1/2 stem (IGEV-Stereo's encoders), `None` otherwise.
    pub pyramid: Option<FeaturePyramid>,
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
    /// The left view's 1/2 image stem, which the superpixel upsampling reads (IGEV-Stereo).
    pub(crate) stem_2: Option<Tensor<4>>,
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
    /// With [`ForwardOptions::upsample_initial`], the x flow the loop started from at full
    /// resolution, where the network upsamples its start itself (IGEV-Stereo's `init_disp`);
    /// `None` otherwise (RAFT-Stereo's zero, DEFOM-Stereo's scaled inverse depth).
    pub initial_flow_up: Option<Tensor<4>>,
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
        let c = &config.correlation;
        let monocular = config.monocular.init(device);
        let depth_channels = monocular.as_ref().map(DepthAnythingV2Features::feature_channels);
        let output = match u.delta_clip {
            // The lookup's reach: `radius` at the coarsest of `levels` levels, in pixels of level 0.
            true => HeadOutput::ClippedDelta { bound: ((1usize << c.levels.saturating_sub(1)) * c.radius) as f32 },
            false => HeadOutput::Delta,
        };
        let scale_update_block = match (&u.scale_update, &c.scale_lookup) {
            (None, _) => None,
            (Some(_), Some(lookup)) => {
                Some(MultiLevelUpdateBlock::new(u, lookup.channels(), HeadOutput::Scale, device))
            }
            (Some(_), None) => {
                return Err(Error::config(
                    "updater.scale_update",
                    "the scale update reads the correlation's scale lookup: set model.correlation.scale_lookup",
                ));
            }
        };
        Ok(Self {
            monocular,
            fusion: config.fusion.init(device)?,
            encoder: config
                .encoder
                .init(dims, u.n_downsample, depth_channels, device)
                .map_err(|e| e.within("encoder"))?,
            geometry: c.geometry.as_ref().map(|g| g.init(device)),
            // Level `i` counts from the finest (1/4, `hidden_dims[2]`) as the context does.
            context_zqr_convs: (0..u.n_gru_layers)
                .map(|i| {
                    let d = dims[2 - i];
                    conv2d([d, d * 3], 3, 1, 1, ConvInit::TorchDefault, device)
                })
                .collect(),
            update_block: MultiLevelUpdateBlock::new(u, c.channels(), output, device),
            superpixel: (u.upsampling == UpsamplingKind::Superpixel).then(|| SuperpixelUpsampler::new(device)),
            scale_update_block,
            scale_iters: u.scale_update.as_ref().map_or(0, |s| s.iters),
            motion: u.motion,
            initial_disparity: config.initial_disparity,
            correlation: c.clone(),
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
        let ForwardOptions { flow_init, implementation, all_iterations, upsample_initial, mut probe } = options;
        let probe = &mut probe;
        let Encodings { fmap1, fmap2, mut hidden, gates, initial, pyramid } = self.encode(left, right, prior, probe)?;
        let implementation = implementation.unwrap_or(self.correlation.implementation);
        let (corr_fn, initial, initial_up) = match (&self.geometry, &pyramid) {
            (Some(geometry), Some(pyramid)) => {
                let (corr_fn, logits) = self.geometry_volume(geometry, &pyramid.levels, fmap2, implementation, probe);
                let start = self.geometry_initial(&logits, pyramid, upsample_initial, probe)?;
                (corr_fn, start.state.or(initial), start.upsampled)
            }
            _ => (self.correlation_volume(fmap1, fmap2, implementation, probe), initial, None),
        };
        let grid = self.update_grid(&hidden[0], prior, pyramid.map(|p| p.stem_2), probe)?;
        // The loop's state: the x flow, or a positive disparity (`MotionKind`), in f32.
        let mut state = match (flow_init, initial) {
            (Some(flow), _) => state_of_flow(self.motion, cast_float(flow, FloatDType::F32)),
            (None, Some(initial)) => initial,
            (None, None) => grid.zero_flow(),
        };
        let mut flow_up = Vec::new();
        // The iterations run the same convolutions: their transformed weights are kept until the
        // loop ends (see `UpdateLoop`); which algorithm each convolution takes is the dispatch's
        // choice, from the `Numerics` the update passes.
        let _update_loop = UpdateLoop::new();
        for k in 0..iters {
            state = state.detach();
            let (block, corr) = match &self.scale_update_block {
                Some(scale_block) if k < self.scale_iters => {
                    (scale_block, self.scale_lookup(&corr_fn, &grid, state.clone(), probe))
                }
                _ => (&self.update_block, self.lookup(&corr_fn, &grid, state.clone(), probe)),
            };
            probe.record(format_args!("iter.{k}.corr"), &corr);
            let update = self.update(block, &mut hidden, &gates, corr, &grid, state.clone(), probe);
            probe.record(format_args!("iter.{k}.prediction"), &update.prediction);
            state = update.apply(state);
            for (i, hi) in hidden.iter().enumerate() {
                probe.record(format_args!("iter.{k}.hidden.{i}"), hi);
            }
            if probe.tracing() {
                probe.record(format_args!("iter.{k}.flow_lowres"), &flow_of_state(self.motion, state.clone()));
            }
            // The mask never feeds back into the state: computed only where it is used.
            let upsampled = all_iterations || k + 1 == iters;
            if upsampled || probe.tracing() {
                let up_mask = self.upsample_weights(block, &hidden, probe);
                probe.record(format_args!("iter.{k}.up_mask"), &up_mask);
                if !upsampled {
                    continue;
                }
                if probe.tracing()
                    && let Some(logits) = self.superpixel_logits(up_mask.clone(), &grid)
                {
                    probe.record(format_args!("iter.{k}.spx_gru"), &logits);
                }
                let up = self.upsample(state.clone(), up_mask, &grid, probe);
                if self.motion == MotionKind::Disparity {
                    probe.record(format_args!("iter.{k}.disparity_up"), &up);
                }
                let up = flow_of_state(self.motion, up);
                probe.record(format_args!("iter.{k}.flow_up"), &up);
                flow_up.push(up);
            }
        }
        let initial_flow_up = initial_up.map(|disparity| disparity.neg());
        Ok(FlowOutput { flow_up, flow_lowres: flow_of_state(self.motion, state), initial_flow_up })
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
    /// (`[N, C, H/f, W/f]`): the positions, the zero y flow, the guidance feature from the left
    /// prior (computed once per pass) and the image stem `stem_2` of the superpixel upsampling.
    pub(crate) fn update_grid(
        &self,
        hidden_fine: &Tensor<4>,
        prior: Option<&DepthPrior>,
        stem_2: Option<Tensor<4>>,
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
        Ok(UpdateGrid { coords0, zeros, guidance, dtype: float_dtype(&device), stem_2 })
    }

    /// Stage 3, one iteration's lookup: the cost volume sampled around each pixel's match at
    /// `x + f` for the x flow `f`, `x - d` for the disparity `d` (the loop's `state`:
    /// `[N, 1, H/f, W/f]`, f32; the geometry volume also at `d` itself), in the update block's
    /// dtype.
    pub(crate) fn lookup(
        &self,
        corr_fn: &Correlation,
        grid: &UpdateGrid,
        state: Tensor<4>,
        probe: &mut Probe<'_>,
    ) -> Tensor<4> {
        let coords0 = grid.coords0.clone();
        probe.time("correlation lookup", || {
            let corr = match self.motion {
                MotionKind::Flow => corr_fn.lookup(coords0 + state),
                MotionKind::Disparity => corr_fn.lookup_disparity(coords0, state),
            };
            cast_float(corr, grid.dtype)
        })
    }

    /// Stage 3 of a scale iteration: the correlation's scale lookup around the matches of the
    /// scaled x flows (`state` as in [`Self::lookup`]), in the update block's dtype.
    pub(crate) fn scale_lookup(
        &self,
        corr_fn: &Correlation,
        grid: &UpdateGrid,
        state: Tensor<4>,
        probe: &mut Probe<'_>,
    ) -> Tensor<4> {
        let Some(lookup) = &self.correlation.scale_lookup else {
            // A scale block exists only with its lookup (`ModelConfig::stage_problems`).
            return self.lookup(corr_fn, grid, state, probe);
        };
        let flow_x = flow_of_state(self.motion, state);
        probe.time("correlation lookup", || {
            cast_float(corr_fn.scale_lookup(grid.coords0.clone(), flow_x, lookup), grid.dtype)
        })
    }

    /// Stage 4, one update step of `block`: advances `hidden` from the lookup `corr` and the
    /// loop's `state` (f32) and returns the block's prediction, in the update block's dtype.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn update(
        &self,
        block: &MultiLevelUpdateBlock,
        hidden: &mut [Tensor<4>],
        gates: &[GateContext],
        corr: Tensor<4>,
        grid: &UpdateGrid,
        state: Tensor<4>,
        probe: &mut Probe<'_>,
    ) -> UpdateOutput {
        let motion = match self.motion {
            MotionKind::Flow => Tensor::cat(vec![cast_float(state, grid.dtype), grid.zeros.clone()], 1),
            MotionKind::Disparity => cast_float(state, grid.dtype),
        };
        block.step(hidden, gates, corr, motion, grid.guidance.as_ref(), probe)
    }

    /// Stage 5a, `block`'s mask head: the convex upsampling's weights from the finest state.
    pub(crate) fn upsample_weights(
        &self,
        block: &MultiLevelUpdateBlock,
        hidden: &[Tensor<4>],
        probe: &mut Probe<'_>,
    ) -> Tensor<4> {
        probe.time("mask head", || block.upsample_mask(hidden))
    }

    /// Stage 5b, the loop's state (f32) to full resolution: convex upsampling by `mask`, or
    /// the superpixel upsampling of IGEV-Stereo from the mask feature `mask` and the grid's
    /// image stem.
    pub(crate) fn upsample(
        &self,
        state: Tensor<4>,
        mask: Tensor<4>,
        grid: &UpdateGrid,
        probe: &mut Probe<'_>,
    ) -> Tensor<4> {
        if let Some(logits) = self.superpixel_logits(mask.clone(), grid) {
            return probe.time("superpixel upsample", || {
                context_upsample(state, softmax(cast_float(logits, FloatDType::F32), 1))
            });
        }
        let factor = 1usize << self.n_downsample;
        probe.time("convex upsample", || convex_upsample(state, cast_float(mask, FloatDType::F32), factor))
    }
}

/// The loop's state of an x flow (f32): the flow itself, or the disparity `-flow`.
pub(crate) fn state_of_flow(motion: MotionKind, flow_x: Tensor<4>) -> Tensor<4> {
    match motion {
        MotionKind::Flow => flow_x,
        MotionKind::Disparity => flow_x.neg(),
    }
}

/// The x flow (f32) of the loop's state: the state itself, or `-disparity`.
pub(crate) fn flow_of_state(motion: MotionKind, state: Tensor<4>) -> Tensor<4> {
    state_of_flow(motion, state)
}
