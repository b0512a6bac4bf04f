//! Per-stage timing of one forward pass.
//!
//! [`profile_forward`] runs [`RaftStereo::forward_flow`] itself with a
//! [`StageClock`](dgstereo_core::timing::StageClock): the production path times its own stages,
//! so there is no second copy of the forward sequence to drift from it. The CPU backend executes
//! every operation eagerly, so the time a stage's closure takes is the time of that stage. Each
//! stage's time is paired with its operation count ([`StageMacs`], per call times calls) so a
//! report can show achieved GFLOP/s.

use burn::tensor::Tensor;
use dgstereo_core::timing::StageClock;
use dgstereo_core::{DepthPrior, Error, Result};

use crate::flops::StageMacs;
use crate::{ForwardOptions, ModelConfig, Probe, RaftStereo};

/// The time and work of one stage, summed over the iterations where it repeats.
#[derive(Debug, Clone, PartialEq)]
pub struct StageTime {
    /// Stage name.
    pub name: &'static str,
    /// Wall-clock seconds, all calls together.
    pub seconds: f64,
    /// CPU seconds of the whole process over the same spans (`NaN` where unknown).
    pub cpu_seconds: f64,
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

    /// Cores busy on average while the stage ran (CPU over wall-clock seconds): below the
    /// machine's core count, cores sat idle. `None` where the CPU time is unknown.
    pub fn cores_busy(&self) -> Option<f64> {
        (self.cpu_seconds.is_finite() && self.seconds > 0.0).then(|| self.cpu_seconds / self.seconds)
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
    config.check_prior(prior.is_some())?;
    if iters == 0 {
        return Err(Error::config("iters", "must be at least 1"));
    }
    let macs = StageMacs::new(config, [h, w]);
    let mut clock = StageClock::synced(left.device());
    let out = model.forward_flow(
        left,
        right,
        prior,
        iters,
        ForwardOptions { probe: Probe::new(None, Some(&mut clock)), ..Default::default() },
    )?;
    // MACs per call of each counted stage; the encoders and the build run once per pass.
    let per_call = |name: &str, calls: usize| -> u64 {
        match name {
            "feature encoder" => macs.feature_encoder / calls.max(1) as u64,
            "context encoder" => macs.context_encoder / calls.max(1) as u64,
            "correlation build" => macs.correlation_build,
            "motion encoder" => macs.motion_encoder,
            "GRU 1/4" => macs.gru_fine,
            "GRU 1/8" => macs.gru_mid,
            "GRU 1/16" => macs.gru_coarse,
            "flow head" => macs.flow_head,
            "mask head" => macs.mask_head,
            "convex upsample" => macs.convex_upsample,
            _ => 0,
        }
    };
    let gru_fine_calls = clock.stages().iter().find(|s| s.name == "GRU 1/4").map_or(0, |s| s.calls);
    let stages = clock
        .stages()
        .iter()
        .map(|s| StageTime {
            name: s.name,
            seconds: s.seconds,
            cpu_seconds: s.cpu_seconds,
            calls: s.calls,
            // The interpolations' count is per update iteration (several calls each).
            macs: if s.name == "interpolation" {
                macs.interpolation * gru_fine_calls as u64
            } else {
                per_call(s.name, s.calls) * s.calls as u64
            },
        })
        .collect();
    let flow_up = out.flow_up.into_iter().last().expect("at least one iteration");
    Ok(Profile { stages, flow_lowres: out.flow_lowres, flow_up })
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::max_abs_diff;

    /// The profiled pass computes what `forward_flow` computes and times every stage.
    #[test]
    fn profile_times_every_stage_of_forward_flow() {
        let device = default_device();
        let mut config = ModelConfig::default();
        config.updater.hidden_dims = [16, 16, 16];
        let model = config.init(&device).unwrap();
        let img = || Tensor::<4>::random([1, 3, 32, 64], Distribution::Uniform(0.0, 255.0), &device);
        let (left, right) = (img(), img());
        let out = model.forward_flow(left.clone(), right.clone(), None, 3, ForwardOptions::default()).unwrap();
        let profile = profile_forward(&model, &config, left, right, None, 3).unwrap();
        assert!(max_abs_diff(profile.flow_lowres.clone(), out.flow_lowres) < 1e-5);
        assert!(max_abs_diff(profile.flow_up.clone(), out.flow_up[0].clone()) < 1e-4);
        let gru = profile.stages.iter().find(|s| s.name == "GRU 1/4").unwrap();
        assert_eq!(gru.calls, 3);
        assert_eq!(profile.stages.iter().find(|s| s.name == "mask head").unwrap().calls, 1);
        let names: Vec<&str> = profile.stages.iter().map(|s| s.name).collect();
        for stage in ["feature encoder", "context encoder", "correlation build", "correlation lookup", "GRU 1/8"] {
            assert!(names.contains(&stage), "{stage} missing from {names:?}");
        }
        // The counted work is the model's, stage by stage.
        let macs = StageMacs::new(&config, [32, 64]);
        let of = |name: &str| profile.stages.iter().find(|s| s.name == name).unwrap().macs;
        assert_eq!(of("GRU 1/4"), 3 * macs.gru_fine);
        assert_eq!(of("feature encoder"), macs.feature_encoder);
        assert!(profile.total_seconds() > 0.0);
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
