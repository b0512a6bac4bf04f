//! Per-stage timing of a training step's backward pass.
//!
//! Design decision: burn's autodiff runs a backward pass by graph depth, not stage by stage (the
//! encoders' nodes come last, each iteration's loss branch interleaves with the next
//! iterations' update), so one pass cannot be split into stages by a clock. Instead
//! [`profile_backward`] runs each stage of [`RaftStereo::forward_flow`] alone, by calling the
//! same stage functions `forward_flow` calls (`encode`, `correlation_volume` with `lookup`,
//! `update`, `upsample_weights` with `upsample`), on the shapes they have in a training step:
//! a stage's inputs are the detached outputs of the stage before (leaves that require gradients,
//! so the gradient into the stage's inputs is computed as in the step), with random flows in
//! place of the iterations' own, its outputs are dotted with fixed random weights into one
//! scalar, and the forward and the backward from that scalar are timed. The stages' backward seconds add up to about a whole step's
//! backward (the dot products and the loss itself are the difference), which `dgstereo bench
//! --train --stages` prints beside the step's own split.

use std::time::Instant;

use burn::optim::GradientsParams;
use burn::tensor::{DType, Device, Distribution, Tensor};
use dgstereo_core::timing::process_cpu_seconds;
use dgstereo_core::{DepthPrior, Probe, Result};
use dgstereo_updater::GateContext;

use crate::RaftStereo;
use crate::network::Encodings;

/// The forward and backward seconds of one stage run alone.
#[derive(Debug, Clone, PartialEq)]
pub struct StageBackward {
    /// Stage name.
    pub name: &'static str,
    /// Wall-clock seconds of the stage's forward (all its calls).
    pub forward_seconds: f64,
    /// Wall-clock seconds of the backward from the stage's outputs to its inputs and weights.
    pub backward_seconds: f64,
    /// CPU seconds of the whole process (all threads) over the backward; `NaN` where unknown.
    /// Over `backward_seconds`: the cores busy on average.
    pub backward_cpu_seconds: f64,
    /// How many times the stage runs in a step (iterations for the update stages).
    pub calls: usize,
    /// How many of the model's parameter tensors its backward reached: the stages share none,
    /// so over all stages this is the count a whole step's backward reaches.
    pub parameters: usize,
}

/// `Σ x·r` over `outputs`, each with its own random `r` (the upstream gradient of the stage).
fn dotted(outputs: &[Tensor<4>]) -> Tensor<1> {
    outputs
        .iter()
        .map(|x| (x.clone() * Tensor::<4>::random(x.dims(), Distribution::Normal(0.0, 1.0), &x.device())).sum())
        .reduce(|a, b| a + b)
        .expect("at least one output")
}

/// A detached copy of `x` that requires a gradient: the input of a stage run alone.
fn leaf(x: &Tensor<4>) -> Tensor<4> {
    x.clone().detach().require_grad()
}

/// Times `forward` (returning the outputs to dot, and a value to hand on) and the backward from
/// the dot product of its outputs, after waiting for `device` around each (needed on a GPU).
fn timed<T>(
    model: &RaftStereo,
    name: &'static str,
    calls: usize,
    device: &Device,
    forward: impl FnOnce() -> Result<(Vec<Tensor<4>>, T)>,
) -> Result<(StageBackward, T)> {
    let wait = || {
        // A failed sync surfaces again at the next read of a result; timing needs no error.
        let _ = device.sync();
    };
    wait();
    let start = Instant::now();
    let (outputs, kept) = forward()?;
    let scalar = dotted(&outputs);
    wait();
    let forward_seconds = start.elapsed().as_secs_f64();
    let (start, cpu_start) = (Instant::now(), process_cpu_seconds());
    let grads = scalar.backward();
    wait();
    let backward_seconds = start.elapsed().as_secs_f64();
    let backward_cpu_seconds = process_cpu_seconds().zip(cpu_start).map_or(f64::NAN, |(end, start)| end - start);
    let parameters = GradientsParams::from_grads(grads, model).len();
    Ok((StageBackward { name, forward_seconds, backward_seconds, backward_cpu_seconds, calls, parameters }, kept))
}

/// Each stage's forward and backward seconds in a training step of `iters` iterations on
/// `left`/`right` (and `prior`, for models that take one): fusion and encoders with the context
/// heads, the correlation volume with its `iters` lookups, the `iters` chained update steps, and
/// the `iters` mask heads with their convex upsampling. `model` must be on an autodiff device.
///
/// # Shapes
/// - `left`, `right`: `[N, 3, H, W]` padded as for [`RaftStereo::forward_flow`]; prior maps `[N, 1, H, W]`
///
/// # Errors
/// As [`RaftStereo::forward_flow`]: the fusion needs the prior and `prior` is `None`.
pub fn profile_backward(
    model: &RaftStereo,
    left: Tensor<4>,
    right: Tensor<4>,
    prior: Option<&DepthPrior>,
    iters: usize,
) -> Result<Vec<StageBackward>> {
    let device = left.device();
    let mut probe = Probe::none();
    let (encoders, encodings) = timed(model, "fusion + encoders", 1, &device, || {
        let encodings = model.encode(left, right, prior, &mut probe)?;
        let mut outputs = vec![encodings.fmap1.clone(), encodings.fmap2.clone()];
        outputs.extend(encodings.hidden.iter().cloned());
        outputs.extend(encodings.gates.iter().flat_map(|g| [g.zr.clone(), g.q.clone()]));
        Ok((outputs, encodings))
    })?;
    let Encodings { fmap1, fmap2, hidden, gates, pyramid, .. } = encodings;

    let [n, _, h, w] = hidden[0].dims();
    let f32_on = (&device, DType::F32);
    let grid = model.update_grid(&hidden[0], prior, pyramid.map(|p| p.stem_2), &mut probe)?;
    // Positions spread as a step's are: a random flow of up to a quarter of the grid's width.
    let flows: Vec<Tensor<4>> = (0..iters)
        .map(|_| Tensor::<4>::random([n, 1, h, w], Distribution::Uniform(-(w as f64) / 4.0, 0.0), f32_on))
        .collect();
    let (correlation, corrs) = timed(model, "correlation", iters, &device, || {
        let implementation = model.correlation.implementation;
        let volume = model.correlation_volume(leaf(&fmap1), leaf(&fmap2), implementation, &mut probe);
        let corrs: Vec<Tensor<4>> =
            flows.iter().map(|flow| model.lookup(&volume, &grid, flow.clone(), &mut probe)).collect();
        Ok((corrs.clone(), corrs))
    })?;

    let (update, states) = timed(model, "update steps", iters, &device, || {
        let mut state: Vec<Tensor<4>> = hidden.iter().map(leaf).collect();
        let context: Vec<GateContext> = gates
            .iter()
            .map(|g| GateContext { z: leaf(&g.z), r: leaf(&g.r), q: leaf(&g.q), zr: leaf(&g.zr) })
            .collect();
        let mut deltas = Vec::with_capacity(iters);
        let mut states = Vec::with_capacity(iters);
        for (corr, flow_x) in corrs.iter().zip(&flows) {
            let block = &model.update_block;
            let update = model.update(block, &mut state, &context, leaf(corr), &grid, flow_x.clone(), &mut probe);
            deltas.push(update.prediction);
            states.push(state[0].clone());
        }
        Ok((deltas, states))
    })?;

    let (upsampling, ()) = timed(model, "mask heads + upsampling", iters, &device, || {
        let up = states
            .iter()
            .zip(&flows)
            .map(|(state, flow_x)| {
                let mask = model.upsample_weights(&model.update_block, &[leaf(state)], &mut probe);
                model.upsample(leaf(flow_x), mask, &grid, &mut probe)
            })
            .collect();
        Ok((up, ()))
    })?;
    Ok(vec![encoders, correlation, update, upsampling])
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution, Tensor};

    use dgstereo_fusion::{FusionConfig, FusionTarget};
    use dgstereo_updater::GuidanceKind;

    use super::*;
    use crate::{ForwardOptions, ModelConfig};

    /// The four stages run with the step's iteration count, and together their backward passes
    /// reach exactly the parameters a whole step's backward reaches: no stage is left out of the
    /// profile and none is counted twice. (No time is asserted: speed is a benchmark's.)
    #[test]
    fn stages_cover_the_step_once() {
        let device = Device::flex().autodiff();
        // The paper's model, CPU-sized: the fusion, the prior and the guidance are in the stages too.
        let mut config = ModelConfig {
            fusion: FusionConfig::Deformable { target: FusionTarget::Both, features: 8 },
            ..ModelConfig::default()
        };
        config.encoder.trunk_dims = [16, 24, 32];
        config.encoder.feature_dim = 32;
        config.updater.hidden_dims = [16, 16, 16];
        config.updater.n_downsample = 3;
        config.updater.guidance = GuidanceKind::Gradient;
        let model = config.init(&device).expect("the model builds");
        let image = || Tensor::<4>::random([1, 3, 64, 128], Distribution::Uniform(0.0, 255.0), &device);
        let (left, right) = (image(), image());
        let depth = || Tensor::<4>::random([1, 1, 64, 128], Distribution::Uniform(0.5, 2.0), &device);
        let prior = DepthPrior { left: depth(), right: depth() };
        let iters = 3;
        let stages = profile_backward(&model, left.clone(), right.clone(), Some(&prior), iters).unwrap();
        let names: Vec<&str> = stages.iter().map(|s| s.name).collect();
        assert_eq!(names, ["fusion + encoders", "correlation", "update steps", "mask heads + upsampling"]);
        assert_eq!(stages.iter().map(|s| s.calls).collect::<Vec<_>>(), [1, iters, iters, iters]);
        assert!(stages.iter().all(|s| s.forward_seconds >= 0.0 && s.backward_seconds >= 0.0));
        assert!(stages.iter().all(|s| s.name == "correlation" || s.parameters > 0), "{stages:?}");

        let options = ForwardOptions { all_iterations: true, ..ForwardOptions::default() };
        let out = model.forward_flow(left, right, Some(&prior), iters, options).unwrap();
        let loss = out.flow_up.into_iter().map(|f| f.abs().sum()).reduce(|a, b| a + b).expect("iterations");
        let whole = GradientsParams::from_grads(loss.backward(), &model).len();
        assert_eq!(stages.iter().map(|s| s.parameters).sum::<usize>(), whole, "{stages:?}");
    }
}
