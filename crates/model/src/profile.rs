//! Per-stage time and work of one forward pass.
//!
//! [`profile_forward`] runs [`RaftStereo::forward_flow`] itself under the kernels' operation
//! count ([`dgstereo_kernels::count_work`]) with a [`StageClock`] metered by that count: the
//! production path times its own stages, and each stage's multiply-accumulates are those its
//! operations counted as they ran (the fusion and every configured variant included), so
//! neither the forward sequence nor its arithmetic is described a second time. The CPU backend
//! executes every operation eagerly, so the time a stage's closure takes is the time of that
//! stage. Each stage's time is paired with its count so a report can show achieved GFLOP/s.

use burn::tensor::Tensor;
use dgstereo_core::timing::StageClock;
use dgstereo_core::{DepthPrior, Error, Result};
use dgstereo_kernels::{count_work, macs_so_far};

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
    /// Multiply-accumulates its operations counted, all calls together (0 for memory-bound
    /// stages).
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
    /// Multiply-accumulates of the whole pass (the stages' together).
    pub macs: u64,
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
    let [n, ..] = left.dims();
    if n != 1 {
        return Err(Error::Shape(format!("the profile runs one pair at a time, got a batch of {n}")));
    }
    config.check_prior(prior.is_some())?;
    if iters == 0 {
        return Err(Error::config("iters", "must be at least 1"));
    }
    let mut clock = StageClock::synced(left.device()).metered(macs_so_far);
    let options = ForwardOptions { probe: Probe::new(None, Some(&mut clock)), ..Default::default() };
    let (out, work) = count_work(|| model.forward_flow(left, right, prior, iters, options));
    let out = out?;
    let stages = clock
        .stages()
        .iter()
        .map(|s| StageTime {
            name: s.name,
            seconds: s.seconds,
            cpu_seconds: s.cpu_seconds,
            calls: s.calls,
            macs: s.work,
        })
        .collect();
    let flow_up = out.flow_up.into_iter().last().expect("at least one iteration");
    Ok(Profile { stages, flow_lowres: out.flow_lowres, flow_up, macs: work.macs })
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
        assert!(profile.total_seconds() > 0.0);
    }

    /// A small model's counted work, stage by stage, against a hand count of its layers at a
    /// 64x128 input (an 16x32 update grid): the fine GRU (three 3x3 convolutions of
    /// `16 + 128 + 16 -> 16` channels), the mask head (3x3 `16 -> 256`, 1x1 `256 -> 144`), the
    /// correlation's product (`W/4` pairs of 256-long features per pixel), the convex upsampling
    /// (9 per full-resolution value) and the feature encoder of both views (stem at full
    /// resolution, layer1 there, layer2 and layer3 halving, the 1x1 projection).
    #[test]
    fn counted_work_matches_a_hand_count() {
        let device = default_device();
        let mut config = ModelConfig::default();
        config.updater.hidden_dims = [16, 16, 16];
        let model = config.init(&device).unwrap();
        let img = || Tensor::<4>::random([1, 3, 64, 128], Distribution::Uniform(0.0, 255.0), &device);
        let iters = 2;
        let profile = profile_forward(&model, &config, img(), img(), None, iters).unwrap();
        let of = |name: &str| profile.stages.iter().find(|s| s.name == name).map_or(0, |s| s.macs);
        let grid = 16 * 32u64;
        assert_eq!(of("GRU 1/4"), iters as u64 * 3 * (16 + 128 + 16) * 16 * 9 * grid);
        assert_eq!(of("mask head"), (16 * 256 * 9 + 256 * 144) * grid);
        assert_eq!(of("correlation build"), grid * 32 * 256);
        assert_eq!(of("convex upsample"), 9 * 64 * 128);
        let full = 64 * 128u64;
        let stem = 3 * 64 * 49 * full;
        let layer1 = 4 * 64 * 64 * 9 * full;
        let layer2 = (64 * 96 * 9 + 3 * 96 * 96 * 9 + 64 * 96) * full / 4;
        let layer3 = (96 * 128 * 9 + 3 * 128 * 128 * 9 + 96 * 128) * grid;
        let projection = 128 * 256 * grid;
        assert_eq!(of("feature encoder"), 2 * (stem + layer1 + layer2 + layer3 + projection));
        // Memory-bound stages count nothing.
        assert_eq!(of("correlation lookup") + of("interpolation"), 0);
    }

    /// The stages' counts add up to the pass's, which is what `forward_flow` does under
    /// `count_work`; a fusion adds exactly its own stage's work to the pass without one.
    #[test]
    fn stage_counts_add_to_the_pass_and_fusion_is_counted() {
        use dgstereo_fusion::{FusionConfig, FusionTarget};
        let device = default_device();
        let img = || Tensor::<4>::random([1, 3, 32, 64], Distribution::Uniform(0.0, 255.0), &device);
        let depth = || Tensor::<4>::random([1, 1, 32, 64], Distribution::Uniform(0.5, 2.0), &device);
        let (left, right, prior) = (img(), img(), DepthPrior { left: depth(), right: depth() });
        let run = |fusion: FusionConfig| {
            let mut config = ModelConfig { fusion, ..ModelConfig::default() };
            config.updater.hidden_dims = [16, 16, 16];
            let model = config.init(&device).unwrap();
            let profile = profile_forward(&model, &config, left.clone(), right.clone(), Some(&prior), 2).unwrap();
            assert_eq!(profile.stages.iter().map(|s| s.macs).sum::<u64>(), profile.macs);
            let options = ForwardOptions::default();
            let (_, work) = count_work(|| model.forward_flow(left.clone(), right.clone(), Some(&prior), 2, options));
            assert_eq!(work.macs, profile.macs);
            let fusion = profile.stages.iter().find(|s| s.name == "fusion").map_or(0, |s| s.macs);
            (profile.macs, fusion)
        };
        let (plain, none) = run(FusionConfig::None {});
        assert_eq!(none, 0);
        for target in [FusionTarget::ContextOnly, FusionTarget::Both] {
            let features = 8;
            for fusion in [FusionConfig::Deformable { target, features }, FusionConfig::Conv { target, features }] {
                let (total, fused) = run(fusion.clone());
                assert!(fused > 0, "{fusion:?}");
                assert_eq!(total, plain + fused, "{fusion:?}");
            }
        }
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
