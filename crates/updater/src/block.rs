//! The multi-level update block of RAFT-Stereo.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::Probe;
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::{average_pool_half, resize_bilinear};
use dgstereo_kernels::{conv2d_forward, conv2d_forward_then, conv2d_relu_forward};

use crate::gru::{ConvGru, GateContext};
use crate::loop_numerics::UPDATE_LOOP;
use crate::motion::{MotionEncoder, MotionKind};
use crate::{HeadOutput, UpdateOutput, UpdaterConfig, UpsamplingKind};

/// Two convolutions predicting the update (`FlowHead`, and DEFOM-Stereo's `DispHead`).
#[derive(Module, Debug)]
pub struct FlowHead {
    /// 3x3 to 256 channels.
    pub conv1: Conv2d,
    /// 3x3 to the motion's channels (x and y of the flow, y discarded; or the disparity).
    pub conv2: Conv2d,
}

/// Two convolutions predicting the convex-upsampling weights (`mask` in the reference, whose
/// `mask.0`/`mask.2` are `conv1`/`conv2` here).
#[derive(Module, Debug)]
pub struct MaskHead {
    /// 3x3 to 256 channels.
    pub conv1: Conv2d,
    /// 1x1 to `9·factor²` channels.
    pub conv2: Conv2d,
}

/// IGEV-Stereo's `mask_feat_4`: a 3x3 convolution to 32 channels and a ReLU, the feature the
/// superpixel upsampling reads (`mask_feat_4.0` in the reference is `conv` here).
#[derive(Module, Debug)]
pub struct MaskFeatureHead {
    /// 3x3 to 32 channels.
    pub conv: Conv2d,
}

/// Channels of IGEV-Stereo's mask feature.
pub const MASK_FEATURE_CHANNELS: usize = 32;

/// ConvGRUs at 1/4, 1/8 and 1/16 (always built, as in the reference), the motion encoder and
/// the two heads (the second one the convex upsampling's `mask` or IGEV-Stereo's `mask_feat_4`,
/// [`crate::UpsamplingKind`]). The update head is `flow_head` (RAFT-Stereo's flow) or `disp_head` (a
/// disparity, [`MotionKind::Disparity`]); what its prediction does is the block's
/// [`HeadOutput`] (DEFOM-Stereo's scale block multiplies).
///
/// One call runs, in the reference's order, the 1/16 GRU (fed by the pooled old 1/8 state),
/// the 1/8 GRU (pooled old 1/4 state and the upsampled new 1/16 state), then the motion encoder
/// and the 1/4 GRU (with the upsampled new 1/8 state), and the flow head on the 1/4 state.
/// With `slow_fast_gru` the coarse levels first run extra updates, as the reference's
/// `raft_stereo.py` schedules them: the 1/16 GRU alone, then the 1/16 and 1/8 GRUs, then all.
#[derive(Module, Debug)]
pub struct MultiLevelUpdateBlock {
    /// Motion encoder.
    pub encoder: MotionEncoder,
    /// GRU at 1/4.
    pub gru08: ConvGru,
    /// GRU at 1/8.
    pub gru16: ConvGru,
    /// GRU at 1/16.
    pub gru32: ConvGru,
    /// Flow head (RAFT-Stereo).
    pub flow_head: Option<FlowHead>,
    /// Disparity head (DEFOM-Stereo's `disp_head`).
    pub disp_head: Option<FlowHead>,
    /// Upsampling-weight head (convex upsampling).
    pub mask: Option<MaskHead>,
    /// Mask-feature head (IGEV-Stereo's superpixel upsampling).
    pub mask_feat_4: Option<MaskFeatureHead>,
    /// GRU levels in use (1..=3).
    pub n_gru_layers: usize,
    /// Extra coarse-level updates before each step (`slow_fast_gru`).
    pub slow_fast_gru: bool,
    /// What the head's prediction does to the state.
    #[module(skip)]
    pub output: HeadOutput,
}

/// `F.avg_pool2d(x, 3, stride=2, padding=1)` (padding counted in the average): a finer
/// state handed to the next coarser GRU.
pub fn pool2x(x: Tensor<4>) -> Tensor<4> {
    average_pool_half(x)
}

/// Bilinear resize (align corners) of `x` to the size of `dest`: a coarser state handed to
/// the next finer GRU.
pub fn interp(x: Tensor<4>, dest: &Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = dest.dims();
    resize_bilinear(x, [h, w], true)
}

impl MultiLevelUpdateBlock {
    /// Builds the block for `corr_channels` lookup channels, its head's prediction applied as
    /// `output`.
    pub fn new(config: &UpdaterConfig, corr_channels: usize, output: HeadOutput, device: &Device) -> Self {
        let [d32, d16, d08] = config.hidden_dims;
        let n = config.n_gru_layers;
        let factor = 1usize << config.n_downsample;
        let init = ConvInit::TorchDefault;
        let motion = config.motion;
        let head = |kind: MotionKind| {
            (motion == kind).then(|| FlowHead {
                conv1: conv2d([d08, 256], 3, 1, 1, init, device),
                conv2: conv2d([256, kind.channels()], 3, 1, 1, init, device),
            })
        };
        Self {
            encoder: MotionEncoder::new(corr_channels, motion, config.guidance.channels(), device),
            gru08: ConvGru::new(d08, 128 + d16 * (n > 1) as usize, device),
            gru16: ConvGru::new(d16, d32 * (n == 3) as usize + d08, device),
            gru32: ConvGru::new(d32, d16, device),
            flow_head: head(MotionKind::Flow),
            disp_head: head(MotionKind::Disparity),
            mask: (config.upsampling == UpsamplingKind::Convex).then(|| MaskHead {
                conv1: conv2d([d08, 256], 3, 1, 1, init, device),
                conv2: conv2d([256, factor * factor * 9], 1, 1, 0, init, device),
            }),
            mask_feat_4: (config.upsampling == UpsamplingKind::Superpixel)
                .then(|| MaskFeatureHead { conv: conv2d([d08, MASK_FEATURE_CHANNELS], 3, 1, 1, init, device) }),
            n_gru_layers: n,
            slow_fast_gru: config.slow_fast_gru,
            output,
        }
    }

    /// The head's prediction from the finest state: the flow head's x channel, or the disparity
    /// head's output; for a scale block ([`HeadOutput::Scale`]) the factor `relu6(exp(x / 4))`.
    ///
    /// # Shapes
    /// - `hidden_fine`: `[N, hidden, H, W]`; output `[N, 1, H, W]`
    pub fn prediction(&self, hidden_fine: Tensor<4>) -> Tensor<4> {
        let head = self.flow_head.as_ref().or(self.disp_head.as_ref()).expect("the constructor builds one head");
        let hidden = conv2d_relu_forward(&head.conv1, hidden_fine, UPDATE_LOOP);
        let x = conv2d_forward(&head.conv2, hidden, UPDATE_LOOP).narrow(1, 0, 1);
        match self.output {
            HeadOutput::Scale => x.mul_scalar(0.25).exp().clamp(0.0, 6.0),
            HeadOutput::Delta | HeadOutput::ClippedDelta { .. } => x,
        }
    }

    /// Updates the coarser GRUs only: the 1/16 level with `iter32`, then the 1/8 level with
    /// `iter16` (levels the block does not use are skipped).
    fn update_coarse(
        &self,
        hidden: &mut [Tensor<4>],
        context: &[GateContext],
        iter32: bool,
        iter16: bool,
        probe: &mut Probe<'_>,
    ) {
        let n = self.n_gru_layers;
        if iter32 && n == 3 {
            let pooled = probe.time("interpolation", || pool2x(hidden[1].clone()));
            hidden[2] = probe.time("GRU 1/16", || self.gru32.forward(hidden[2].clone(), &context[2], vec![pooled]));
        }
        if iter16 && n >= 2 {
            let mut inputs = vec![probe.time("interpolation", || pool2x(hidden[0].clone()))];
            if n > 2 {
                inputs.push(probe.time("interpolation", || interp(hidden[2].clone(), &hidden[1])));
            }
            hidden[1] = probe.time("GRU 1/8", || self.gru16.forward(hidden[1].clone(), &context[1], inputs));
        }
    }
}

impl MultiLevelUpdateBlock {
    /// One iteration: updates `hidden` in place and predicts the flow update.
    ///
    /// `hidden` and `context` are ordered finest level first; `flow` is `[N, 2, H, W]` (x, y=0),
    /// `corr` the correlation lookup, `guidance` the feature of
    /// [`GuidanceKind::feature`](crate::GuidanceKind::feature). The step includes the configured
    /// schedule of the coarse levels (`slow_fast_gru`). On a `probe` with a clock, each GRU
    /// level, the motion encoder, the interpolations and the flow head are timed as stages
    /// (`GRU 1/4`, `motion encoder`, ...).
    pub fn step(
        &self,
        hidden: &mut [Tensor<4>],
        context: &[GateContext],
        corr: Tensor<4>,
        flow: Tensor<4>,
        guidance: Option<&Tensor<4>>,
        probe: &mut Probe<'_>,
    ) -> UpdateOutput {
        let n = self.n_gru_layers;
        if self.slow_fast_gru {
            self.update_coarse(hidden, context, true, false, probe);
            self.update_coarse(hidden, context, true, true, probe);
        }
        self.update_coarse(hidden, context, true, true, probe);
        let motion = probe.time("motion encoder", || self.encoder.forward_parts(flow, corr, guidance));
        let mut inputs = Vec::from(motion);
        if n > 1 {
            inputs.push(probe.time("interpolation", || interp(hidden[1].clone(), &hidden[0])));
        }
        hidden[0] = probe.time("GRU 1/4", || self.gru08.forward(hidden[0].clone(), &context[0], inputs));
        let prediction = probe.time("flow head", || self.prediction(hidden[0].clone()));
        UpdateOutput { prediction, output: self.output }
    }

    /// The upsampling's input from the current state: the convex-upsampling weights, `[N, 9·f²,
    /// H, W]` (the mask head's logits scaled by 0.25 as in the reference), or for
    /// [`UpsamplingKind::Superpixel`] the mask feature, `[N, 32, H, W]`.
    ///
    /// Separate from [`Self::step`] because the mask never feeds back into the state: a caller
    /// computes it only for the iterations whose full-resolution flow it needs (the last one in
    /// inference), which saves a sixth of every other iteration's work.
    pub fn upsample_mask(&self, hidden: &[Tensor<4>]) -> Tensor<4> {
        if let Some(head) = &self.mask_feat_4 {
            return conv2d_relu_forward(&head.conv, hidden[0].clone(), UPDATE_LOOP);
        }
        let mask = self.mask.as_ref().expect("the constructor builds one of the two heads");
        let features = conv2d_relu_forward(&mask.conv1, hidden[0].clone(), UPDATE_LOOP);
        conv2d_forward_then(&mask.conv2, features, UPDATE_LOOP, |m| m.mul_scalar(0.25))
    }
}
