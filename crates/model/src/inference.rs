//! The public inference API: any image size in, positive disparity out.

use burn::tensor::{Device, Tensor};
use dgstereo_core::DepthPrior;
use dgstereo_core::{Error, InputPadder, Result};
use dgstereo_costvolume::CorrelationImplementation;

use crate::{ForwardOptions, ModelConfig, RaftStereo};

/// A network ready for inference.
///
/// Inputs of any size are padded by replicating their border to a multiple of 32 (RAFT-Stereo's
/// evaluation padder), and results are cropped back, so disparity maps have the input's size.
/// Disparity is positive: `d = x_left - x_right = -flow`.
#[derive(Debug)]
pub struct StereoModel {
    /// The network.
    pub network: RaftStereo,
    /// Its configuration.
    pub config: ModelConfig,
    /// Device of the weights.
    pub device: Device,
}

/// What [`StereoModel::predict`] returns: the network's disparity tensors, one per iteration
/// kept. (A caller's finished prediction of a pair, at its size with what was done on the way,
/// is the inference crate's `Prediction`.)
///
/// # Shapes
/// - each disparity: `[N, 1, H, W]`, the input's size
#[derive(Debug, Clone)]
pub struct IterationDisparities {
    /// Disparity after each iteration (or only the last, see `all_iterations`).
    pub disparities: Vec<Tensor<4>>,
}

impl IterationDisparities {
    /// The final disparity.
    pub fn last(&self) -> Tensor<4> {
        self.disparities.last().expect("at least one iteration").clone()
    }
}

impl StereoModel {
    /// Wraps a network.
    pub fn new(network: RaftStereo, config: ModelConfig, device: Device) -> Self {
        Self { network, config, device }
    }

    /// Disparity of rectified pairs (`[N, 3, H, W]`, RGB 0..255) after `iters` iterations.
    ///
    /// `all_iterations` keeps every iteration's map (for analysis and training); otherwise only
    /// the last is upsampled. `implementation` overrides the configured cost volume.
    pub fn predict(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        prior: Option<&DepthPrior>,
        iters: usize,
        all_iterations: bool,
        implementation: Option<CorrelationImplementation>,
    ) -> Result<IterationDisparities> {
        let [n, c, h, w] = left.dims();
        if right.dims() != [n, c, h, w] {
            return Err(Error::Shape(format!(
                "left image is {w}x{h} but right image is {}x{}: a rectified pair has one size",
                right.dims()[3],
                right.dims()[2]
            )));
        }
        if c != 3 {
            return Err(Error::Shape(format!("images must have 3 channels, found {c}")));
        }
        if iters == 0 {
            return Err(Error::config("iters", "must be at least 1"));
        }
        self.config.check_prior(prior.is_some())?;
        let options = ForwardOptions { implementation, all_iterations, ..ForwardOptions::default() };
        let disparities = padded_disparities(&self.network, &self.config, left, right, prior, iters, options)?;
        Ok(IterationDisparities { disparities })
    }
}

/// What a training pass gives its loss ([`padded_training_disparities`]).
///
/// # Shapes
/// - each disparity: `[N, 1, H, W]`, the input's size
#[derive(Debug, Clone)]
pub struct TrainingDisparities {
    /// Positive disparity after every iteration, first first.
    pub iterations: Vec<Tensor<4>>,
    /// The positive disparity the loop started from, upsampled by the network itself (IGEV-Stereo's
    /// `init_disp`); `None` for a network whose start is not upsampled (RAFT-Stereo's zero,
    /// DEFOM-Stereo's scaled inverse depth, which its official loss does not supervise).
    pub initial: Option<Tensor<4>>,
}

/// Runs `network` on inputs of any size: pads them (and the prior) by replicating the border to
/// a multiple of [`ModelConfig::pad_divisor`], and returns positive disparity, cropped back, for
/// every iteration kept (`options`: the cost volume, every iteration or the last, a probe; the
/// initial flow is at the padded grid). Inputs are not checked: [`StereoModel::predict`] is the
/// checked entry point; the ONNX exporter records this.
///
/// # Errors
/// As [`RaftStereo::forward_flow`]: the fusion needs the prior and `prior` is `None`.
///
/// # Shapes
/// - `left`, `right`: `[N, 3, H, W]`, RGB 0..255; prior maps `[N, 1, H, W]`
/// - each output: `[N, 1, H, W]`
pub fn padded_disparities(
    network: &RaftStereo,
    config: &ModelConfig,
    left: Tensor<4>,
    right: Tensor<4>,
    prior: Option<&DepthPrior>,
    iters: usize,
    options: ForwardOptions<'_>,
) -> Result<Vec<Tensor<4>>> {
    padded_pass(network, config, left, right, prior, iters, options).map(|d| d.iterations)
}

/// The training pass of `network` on a batch it built itself, of any size (padded as
/// [`padded_disparities`] does): every iteration's disparity and the upsampled initial one.
///
/// # Errors
/// As [`RaftStereo::forward_flow`].
pub fn padded_training_disparities(
    network: &RaftStereo,
    config: &ModelConfig,
    left: Tensor<4>,
    right: Tensor<4>,
    prior: Option<&DepthPrior>,
    iters: usize,
) -> Result<TrainingDisparities> {
    let options = ForwardOptions { all_iterations: true, upsample_initial: true, ..ForwardOptions::default() };
    padded_pass(network, config, left, right, prior, iters, options)
}

fn padded_pass(
    network: &RaftStereo,
    config: &ModelConfig,
    left: Tensor<4>,
    right: Tensor<4>,
    prior: Option<&DepthPrior>,
    iters: usize,
    options: ForwardOptions<'_>,
) -> Result<TrainingDisparities> {
    let [_, _, h, w] = left.dims();
    let padder = InputPadder::new(h, w, config.pad_divisor());
    let padded_prior =
        prior.map(|p| DepthPrior { left: padder.pad(p.left.clone()), right: padder.pad(p.right.clone()) });
    let out = network.forward_flow(padder.pad(left), padder.pad(right), padded_prior.as_ref(), iters, options)?;
    let disparity = |flow: Tensor<4>| padder.unpad(flow).neg();
    Ok(TrainingDisparities {
        iterations: out.flow_up.into_iter().map(disparity).collect(),
        initial: out.initial_flow_up.map(disparity),
    })
}
