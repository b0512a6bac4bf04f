//! Per-stage timing of one forward pass.
//!
//! Design decision: [`profile_forward`] re-runs the forward pass of
//! [`crate::RaftStereo::forward_flow`] stage by stage through the same public modules, with a
//! clock around each call, rather than threading timers through the production path. The CPU
//! backend executes every operation eagerly, so the time between two calls is the time of the
//! stage between them. Each stage's time is paired with its operation count ([`StageMacs`]) so a
//! report can show achieved GFLOP/s. The result is checked against `forward_flow` in the tests,
//! so the profiled sequence cannot drift from the real one unnoticed.

use std::time::Instant;

use burn::tensor::activation::{relu, tanh};
use burn::tensor::{Int, Tensor};
use dgstereo_core::{DepthPrior, Error, Result};
use dgstereo_costvolume::CostVolume;
use dgstereo_encoder::{ContextExtractor, FeatureExtractor};
use dgstereo_fusion::ImageFusion;
use dgstereo_updater::block::{interp, pool2x};
use dgstereo_updater::{GateContext, convex_upsample};

use crate::flops::StageMacs;
use crate::{ModelConfig, RaftStereo};

/// The time and work of one stage, summed over the iterations where it repeats.
#[derive(Debug, Clone, PartialEq)]
pub struct StageTime {
    /// Stage name.
    pub name: &'static str,
    /// Wall-clock seconds, all calls together.
    pub seconds: f64,
    /// How many times it ran (iterations for the update stages).
    pub calls: usize,
    /// Multiply-accumulates, all calls together (0 for memory-bound stages).
    pub macs: u64,
}

impl StageTime {
    /// Achieved GFLOP/s (2 FLOP per MAC); `None` for uncounted stages.
    pub fn gflops(&self) -> Option<f64> {
        (self.macs > 0 && self.seconds > 0.0).then(|| 2.0 * self.macs as f64 / self.seconds / 1e9)
    }
}

/// The stages of one profiled pass, in execution order, and its final low-resolution flow.
#[derive(Debug, Clone)]
pub struct Profile {
    /// One entry per stage.
    pub stages: Vec<StageTime>,
    /// x flow at the update grid after the last iteration (to check against `forward_flow`).
    pub flow_lowres: Tensor<4>,
    /// The upsampled final flow.
    pub flow_up: Tensor<4>,
}

impl Profile {
    /// Seconds of all stages together.
    pub fn total_seconds(&self) -> f64 {
        self.stages.iter().map(|s| s.seconds).sum()
    }
}

struct Clock {
    stages: Vec<StageTime>,
}

impl Clock {
    fn time<T>(&mut self, name: &'static str, macs: u64, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        let seconds = start.elapsed().as_secs_f64();
        match self.stages.iter_mut().find(|s| s.name == name) {
            Some(s) => {
                s.seconds += seconds;
                s.calls += 1;
                s.macs += macs;
            }
            None => self.stages.push(StageTime { name, seconds, calls: 1, macs }),
        }
        out
    }
}

/// Runs `model` on one padded pair for `iters` iterations and times every stage; only the last
/// iteration is upsampled, as in inference.
///
/// # Shapes
/// - `left`, `right`: `[1, 3, H, W]`, RGB 0..255, `H` and `W` multiples of 32
///
/// # Errors
/// When the model needs a depth prior and none is given, or the batch is not a single pair.
pub fn profile_forward(
    model: &RaftStereo,
    config: &ModelConfig,
    left: Tensor<4>,
    right: Tensor<4>,
    prior: Option<&DepthPrior>,
    iters: usize,
) -> Result<Profile> {
    let [n, _, h, w] = left.dims();
    if n != 1 {
        return Err(Error::Shape(format!("the profile runs one pair at a time, got a batch of {n}")));
    }
    if config.needs_prior() && prior.is_none() {
        return Err(Error::Config("this model uses a depth prior but none was given to the profiler".into()));
    }
    if iters == 0 {
        return Err(Error::Config("iterations must be at least 1".into()));
    }
    let macs = StageMacs::new(config, [h, w]);
    let mut clock = Clock { stages: Vec::new() };
    let levels = model.n_gru_layers;
    let normalise = |x: Tensor<4>| x.div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0);

    let fused_left = clock.time("fusion", 0, || model.fusion.fuse(left.clone(), prior.map(|p| p.left.clone())));
    let (feat_left, feat_right) = if model.fuse_features {
        let r = clock.time("fusion", 0, || model.fusion.fuse(right.clone(), prior.map(|p| p.right.clone())));
        (fused_left.clone(), r)
    } else {
        (left, right)
    };
    let (context, fmap1, fmap2) = match (&model.fnet, &model.conv2) {
        (Some(fnet), _) => {
            let f1 = clock.time("feature encoder", macs.feature_encoder / 2, || fnet.features(normalise(feat_left)));
            let f2 = clock.time("feature encoder", macs.feature_encoder / 2, || fnet.features(normalise(feat_right)));
            let context = clock.time("context encoder", 0, || model.cnet.context(normalise(fused_left), levels));
            (context, f1, f2)
        }
        (None, Some(head)) => {
            let trunk = clock.time("context encoder", 0, || {
                model.cnet.trunk(normalise(Tensor::cat(vec![fused_left, feat_right], 0)))
            });
            let context = clock.time("context encoder", 0, || model.cnet.heads(trunk.clone().narrow(0, 0, 1), levels));
            let feats = clock.time("feature encoder", macs.feature_encoder, || head.forward(trunk));
            (context, feats.clone().narrow(0, 0, 1), feats.narrow(0, 1, 1))
        }
        (None, None) => return Err(Error::Config("a network has either fnet or conv2".into())),
    };
    let mut hidden = Vec::with_capacity(levels);
    let mut gates = Vec::with_capacity(levels);
    clock.time("context encoder", macs.context_encoder, || {
        for (i, [hh, c]) in context.levels.into_iter().enumerate() {
            hidden.push(tanh(hh));
            gates.push(GateContext::from_zqr(model.context_zqr_convs[i].forward(relu(c))));
        }
    });
    let corr = clock.time("correlation build", macs.correlation_build, || model.correlation.build(fmap1, fmap2));

    let [_, _, h4, w4] = hidden[0].dims();
    let device = hidden[0].device();
    let guidance = prior.and_then(|p| model.guidance.feature(p.left.clone(), [h4, w4]));
    let coords0 = Tensor::<1, Int>::arange(0..w4 as i64, &device).float().reshape([1, 1, 1, w4]).expand([1, 1, h4, w4]);
    let mut flow_x = Tensor::<4>::zeros([1, 1, h4, w4], &device);
    let zeros = Tensor::<4>::zeros([1, 1, h4, w4], &device);
    let block = &model.update_block;
    let mut flow_up = None;
    for k in 0..iters {
        let lookup = clock.time("correlation lookup", 0, || corr.lookup(coords0.clone() + flow_x.clone()));
        if model.slow_fast_gru {
            clock.time("slow-fast extra GRU", 0, || {
                if levels == 3 {
                    block.update_coarse(&mut hidden, &gates, true, false);
                }
                if levels >= 2 {
                    block.update_coarse(&mut hidden, &gates, levels == 3, true);
                }
            });
        }
        if levels == 3 {
            let pooled = clock.time("interpolation", 0, || pool2x(hidden[1].clone()));
            hidden[2] = clock
                .time("GRU 1/16", macs.gru_coarse, || block.gru32.forward(hidden[2].clone(), &gates[2], vec![pooled]));
        }
        if levels >= 2 {
            let mut inputs = vec![clock.time("interpolation", 0, || pool2x(hidden[0].clone()))];
            if levels > 2 {
                inputs.push(
                    clock.time("interpolation", macs.interpolation / 2, || interp(hidden[2].clone(), &hidden[1])),
                );
            }
            hidden[1] =
                clock.time("GRU 1/8", macs.gru_mid, || block.gru16.forward(hidden[1].clone(), &gates[1], inputs));
        }
        let flow = Tensor::cat(vec![flow_x.clone(), zeros.clone()], 1);
        let motion = clock
            .time("motion encoder", macs.motion_encoder, || block.encoder.forward(flow, lookup, guidance.as_ref()));
        let mut inputs = vec![motion];
        if levels > 1 {
            let share = macs.interpolation - macs.interpolation / 2 * (levels > 2) as u64;
            inputs.push(clock.time("interpolation", share, || interp(hidden[1].clone(), &hidden[0])));
        }
        hidden[0] = clock.time("GRU 1/4", macs.gru_fine, || block.gru08.forward(hidden[0].clone(), &gates[0], inputs));
        let delta = clock.time("flow head", macs.flow_head, || block.delta_x(hidden[0].clone()));
        flow_x = flow_x + delta;
        if k + 1 == iters {
            let mask = clock.time("mask head", macs.mask_head, || block.upsample_mask(hidden[0].clone()));
            let factor = 1usize << model.n_downsample;
            flow_up = Some(
                clock.time("convex upsample", macs.convex_upsample, || convex_upsample(flow_x.clone(), mask, factor)),
            );
        }
    }
    let flow_up = flow_up.expect("at least one iteration");
    Ok(Profile { stages: clock.stages, flow_lowres: flow_x, flow_up })
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::max_abs_diff;

    /// The profiled sequence computes what `forward_flow` computes (small widths, tiny image).
    #[test]
    fn profile_matches_forward_flow() {
        let device = default_device();
        let mut config = ModelConfig::default();
        config.updater.hidden_dims = [16, 16, 16];
        let model = config.init(&device).unwrap();
        let img = || Tensor::<4>::random([1, 3, 32, 64], Distribution::Uniform(0.0, 255.0), &device);
        let (left, right) = (img(), img());
        let out = model.forward_flow(left.clone(), right.clone(), None, 3, None, None, false, None);
        let profile = profile_forward(&model, &config, left, right, None, 3).unwrap();
        assert!(max_abs_diff(profile.flow_lowres, out.flow_lowres) < 1e-5);
        assert!(max_abs_diff(profile.flow_up, out.flow_up[0].clone()) < 1e-4);
        let gru = profile.stages.iter().find(|s| s.name == "GRU 1/4").unwrap();
        assert_eq!(gru.calls, 3);
        assert_eq!(profile.stages.iter().find(|s| s.name == "mask head").unwrap().calls, 1);
    }

    #[test]
    fn batches_are_refused() {
        let device = default_device();
        let config = ModelConfig::default();
        let model = config.init(&device).unwrap();
        let img = Tensor::<4>::zeros([2, 3, 32, 32], &device);
        assert!(profile_forward(&model, &config, img.clone(), img, None, 1).is_err());
    }
}
