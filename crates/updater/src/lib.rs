//! The iterative update operator of RAFT-Stereo, with the paper's depth guidance.
//!
//! The update stage, [`MultiLevelUpdateBlock`], takes the GRU states, the precomputed context
//! terms, the correlation lookup, the current disparity and (optionally) a guidance feature, and
//! returns the disparity update ([`UpdateOutput`], [`MultiLevelUpdateBlock::step`]); the
//! convex-upsampling weights are asked for apart ([`MultiLevelUpdateBlock::upsample_mask`]), only
//! for the iterations whose full-resolution disparity is used. It is RAFT-Stereo's three-level
//! ConvGRU; its motion encoder gains a guidance branch when [`GuidanceKind`] is not
//! `none`, so the guidance reaches the GRU input but never the disparity head directly. Bilinear
//! resizes between levels are matrix products (see `dgstereo_kernels::resize_bilinear`), which train on
//! every backend.
//!
//! DEFOM-Stereo's variants: the loop may iterate a positive disparity instead of the x flow
//! ([`MotionKind`]), clip each additive update to the lookup's reach (`delta_clip`), and run a
//! second block first ([`ScaleUpdateConfig`]) whose head multiplies the disparity
//! ([`HeadOutput::Scale`]).
//!
//! IGEV-Stereo's block is the same with the disparity motion and, for its superpixel
//! upsampling ([`superpixel`], [`UpsamplingKind::Superpixel`]) instead of the convex one, a
//! mask-feature head (`mask_feat_4`) in place of the convex-upsampling weights.
//!
//! Design decision: the stage has one implementation, so its contract is that block's own
//! methods and no trait: every variant (guidance, motion, clip, scale head, upsampling head) is
//! a field of the one block chosen by [`UpdaterConfig`], and the model calls the block itself.
#![deny(missing_docs)]

pub mod block;
pub mod gru;
pub mod guidance;
mod loop_numerics;
pub mod motion;
pub mod superpixel;

use burn::tensor::{FloatDType, Tensor};
use dgstereo_core::Problem;
use dgstereo_core::tensor::cast_float;
use serde::{Deserialize, Serialize};

pub use block::{MaskFeatureHead, MultiLevelUpdateBlock};
pub use dgstereo_kernels::convex_upsample;
pub use gru::{ConvGru, GateContext};
pub use guidance::{GuidanceKind, gradient_feature};
pub use motion::MotionKind;
pub use superpixel::{SuperpixelUpsampler, context_upsample};

/// What a block's head predicts and how it changes the iterated state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum HeadOutput {
    /// An additive update (RAFT-Stereo).
    #[default]
    Delta,
    /// An additive update clipped to `±bound` (DEFOM-Stereo: `2^(levels-1)·radius`, the
    /// lookup's reach).
    ClippedDelta {
        /// The largest magnitude of an update.
        bound: f32,
    },
    /// A factor `relu6(exp(x / 4))` of the head's output `x` (DEFOM-Stereo's scale update).
    Scale,
}

/// What one update step returns.
///
/// # Shapes
/// - `prediction`: `[N, 1, H, W]` at the update grid
#[derive(Debug, Clone)]
pub struct UpdateOutput {
    /// The head's prediction: the state's additive update before any clip, or its factor.
    pub prediction: Tensor<4>,
    /// How the prediction applies.
    pub output: HeadOutput,
}

impl UpdateOutput {
    /// The iterated `state` after this update (the prediction cast to the state's dtype):
    /// `state + delta`, `state + clip(delta, ±bound)` or `factor · state`.
    pub fn apply(self, state: Tensor<4>) -> Tensor<4> {
        let prediction = cast_float(self.prediction, FloatDType::from(state.dtype()));
        match self.output {
            HeadOutput::Delta => state + prediction,
            HeadOutput::ClippedDelta { bound } => state + prediction.clamp(-bound, bound),
            HeadOutput::Scale => prediction * state,
        }
    }
}

/// Configuration of the update stage (RAFT-Stereo's defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UpdaterConfig {
    /// Hidden widths, coarsest first (`hidden_dims`: 1/16, 1/8, 1/4).
    #[serde(default = "default_hidden")]
    pub hidden_dims: [usize; 3],
    /// GRU levels in use, 1..=3.
    #[serde(default = "default_layers")]
    pub n_gru_layers: usize,
    /// Update grid at `1/2^n_downsample`; the upsampling factor.
    #[serde(default = "default_downsample")]
    pub n_downsample: usize,
    /// Extra coarse-level updates per iteration (`slow_fast_gru`).
    #[serde(default)]
    pub slow_fast_gru: bool,
    /// The guidance branch.
    #[serde(default)]
    pub guidance: GuidanceKind,
    /// What the loop iterates: the x flow (RAFT-Stereo) or a positive disparity (DEFOM-Stereo).
    #[serde(default)]
    pub motion: MotionKind,
    /// Clip each additive update to `±2^(levels-1)·radius` of the correlation lookup
    /// (DEFOM-Stereo); off in RAFT-Stereo.
    #[serde(default)]
    pub delta_clip: bool,
    /// A scale update block run for the first iterations (DEFOM-Stereo); none in RAFT-Stereo.
    #[serde(default)]
    pub scale_update: Option<ScaleUpdateConfig>,
    /// How the update grid's disparity reaches full resolution, which decides the block's
    /// second head.
    #[serde(default)]
    pub upsampling: UpsamplingKind,
}

/// How the loop's state is upsampled to full resolution, and so what the update block's second
/// head gives ([`MultiLevelUpdateBlock::upsample_mask`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum UpsamplingKind {
    /// RAFT-Stereo's convex upsampling: the head (`mask`) gives `9·f²` weights per pixel.
    #[default]
    Convex,
    /// IGEV-Stereo's superpixel upsampling ([`SuperpixelUpsampler`]): the head (`mask_feat_4`, a
    /// 3x3 convolution and a ReLU) gives a 32-channel feature from which the network's upsampler
    /// derives 9 weights per full-resolution pixel.
    Superpixel,
}

/// DEFOM-Stereo's scale update: a second update block, reading the correlation's scale lookup,
/// whose head multiplies the disparity ([`HeadOutput::Scale`]); it runs instead of the normal
/// block for the first `iters` iterations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleUpdateConfig {
    /// Iterations that run the scale block (`scale_iters`: 8 in DEFOM-Stereo's evaluation and
    /// training).
    #[serde(default = "default_scale_iters")]
    pub iters: usize,
}

fn default_scale_iters() -> usize {
    8
}

impl Default for ScaleUpdateConfig {
    fn default() -> Self {
        Self { iters: default_scale_iters() }
    }
}

fn default_hidden() -> [usize; 3] {
    [128, 128, 128]
}
fn default_layers() -> usize {
    3
}
fn default_downsample() -> usize {
    2
}

impl Default for UpdaterConfig {
    fn default() -> Self {
        Self {
            hidden_dims: default_hidden(),
            n_gru_layers: 3,
            n_downsample: 2,
            slow_fast_gru: false,
            guidance: GuidanceKind::None,
            motion: MotionKind::Flow,
            delta_clip: false,
            scale_update: None,
            upsampling: UpsamplingKind::Convex,
        }
    }
}

impl UpdaterConfig {
    /// Everything wrong with the options, keys relative to the updater table: the GRU levels
    /// (1 to 3), the update grid (`n_downsample` 2 or 3) and the hidden widths (positive).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        if !(1..=3).contains(&self.n_gru_layers) {
            problems.push(Problem::new("n_gru_layers", format!("{} is not 1, 2 or 3", self.n_gru_layers)));
        }
        if !(2..=3).contains(&self.n_downsample) {
            problems.push(Problem::new("n_downsample", format!("{} is not 2 or 3", self.n_downsample)));
        }
        if self.hidden_dims.contains(&0) {
            problems.push(Problem::new("hidden_dims", format!("{:?}: every width must be positive", self.hidden_dims)));
        }
        problems
    }
}
