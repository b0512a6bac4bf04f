//! `dgstereo bench --train`: timing of whole training steps
//! ([`dgstereo_train::timed_steps::time_steps`]: the call `dgstereo train` makes, on a batch of
//! random pairs of the requested size, without data loading, split by the trainer's own clock).
//! The operation count is three times the forward's (the backward's products are twice the
//! forward's), an estimate. `--stages` runs each stage alone as well
//! ([`dgstereo_model::stage_backward`]), since one backward pass cannot be split by stage. Under
//! `mpirun` (a build with the `mpi` feature) `--batch` is the global batch, each rank steps on its
//! part, and the gradient exchange's seconds, bytes and share of the step are reported.

use std::process::ExitCode;

use anyhow::{Context, bail};
use dgstereo_collective::Collective;
use dgstereo_core::DeviceChoice;
use dgstereo_core::timing::{median, peak_memory_bytes};
use dgstereo_inference::model_config_file;
use dgstereo_kernels::{Op, Path, Settings, machine_line, path};
use dgstereo_train::batch::TensorBatch;
use dgstereo_train::step_timing::{StageBackward, StepSeconds, random_batch};
use dgstereo_train::timed_steps::time_steps;
use dgstereo_train::{TrainParts, Trainer};

use crate::measurement::{BenchArgs, parse_size};

/// Times `a.runs` training steps after `a.warmup` (`dgstereo bench --train`).
pub fn run(a: &BenchArgs) -> anyhow::Result<ExitCode> {
    let world = dgstereo_distributed::join()?;
    world.share_cores();
    let [h, w] = parse_size(&a.size)?;
    if a.iters == 0 || a.runs == 0 {
        bail!("--iters and --runs must be at least 1");
    }
    let settings: Settings = a.kernels.parse().with_context(|| format!("--kernels '{}'", a.kernels))?;
    dgstereo_kernels::configure(settings)?;
    let device = &a.device.parse::<DeviceChoice>()?.device_for_local_rank(world.local_rank(), world.local_size())?;
    if a.batch == 0 {
        bail!("--batch must be at least 1");
    }
    if a.weights.is_some() {
        bail!("--weights: a training step costs the same whatever the weights; `bench --train` times fresh ones");
    }
    dgstereo_train::data_parallel::check_batch_divides(a.batch, world.size()).context("--batch")?;
    let config = match &a.experiment {
        Some(p) => dgstereo_experiment::load_first(p)?.config,
        None => dgstereo_experiment::ExperimentConfig::named("bench"),
    };
    let mut parts = TrainParts::from(config);
    if let Some(p) = &a.config {
        parts.model = model_config_file(p).map_err(crate::engine::with_flags)?;
    }
    parts.train.iters = a.iters;
    parts.train.batch_size = a.batch;
    parts.train.crop = [h, w];
    let mut trainer = Trainer::new(crate::fetching::parts(parts)?, device)?;
    let batch = random_batch(a.batch / world.size(), [h, w], (w / 4) as f32, trainer.autodiff_device());
    let kernels = match path(trainer.autodiff_device(), Op::Conv) {
        Path::Host => "host convolution backward",
        Path::Gpu | Path::Stock => "stock",
    };
    let timing = time_steps(&mut trainer, &batch, &world, a.warmup, a.runs)?;
    let (runs, macs) = (&timing.steps, timing.macs);
    let mut times: Vec<f64> = runs.iter().map(|r| r.0).collect();
    let part = |f: fn(&StepSeconds) -> f64| median(&mut runs.iter().map(|r| f(&r.1)).collect::<Vec<_>>());
    let (forward, backward, optimizer) = (part(|s| s.forward), part(|s| s.backward), part(|s| s.optimizer));
    let all_reduce = part(|s| s.all_reduce);
    if world.rank() != 0 {
        return Ok(ExitCode::SUCCESS);
    }
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    let med = median(&mut times);
    println!(
        "training step: batch {} of {h}x{w}, {} iterations, loss {:?}, device {}, {kernels}, {} threads",
        a.batch,
        a.iters,
        trainer.parts().loss,
        a.device,
        rayon::current_num_threads()
    );
    println!("{}", machine_line());
    println!(
        "steps {} after {} warm-up: median {med:.3} s, min {min:.3} s, {:.3} steps/s",
        a.runs,
        a.warmup,
        1.0 / med
    );
    println!("median split: forward {forward:.3} s, backward {backward:.3} s, optimizer {optimizer:.3} s");
    if world.size() > 1 {
        println!(
            "ranks {} ({} on this machine, {} threads each): all-reduce median {all_reduce:.3} s of {:.1} MiB per rank, {:.1} % of the step",
            world.size(),
            world.local_size(),
            rayon::current_num_threads(),
            trainer.last_exchange_bytes() as f64 / (1024.0 * 1024.0),
            100.0 * all_reduce / med
        );
    }
    let per_rank = if world.size() > 1 { " of this rank" } else { "" };
    println!(
        "work{per_rank} ~{:.1} GFLOP (3x the forward's direct convolutions): {:.1} GFLOP/s",
        6.0 * macs as f64 / 1e9,
        6.0 * macs as f64 / med / 1e9
    );
    match peak_memory_bytes() {
        Some(b) => println!("peak memory (VmHWM, whole process) {:.0} MiB", b as f64 / (1024.0 * 1024.0)),
        None => println!("peak memory: not reported by this OS"),
    }
    if a.stages {
        print_stages(&trainer, &batch, backward)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The `--stages` table: each stage run alone ([`Trainer::stage_backward_seconds`]), the median of
/// `runs` passes, beside the whole step's median backward.
fn print_stages(trainer: &Trainer, batch: &TensorBatch, step_backward: f64) -> anyhow::Result<()> {
    let runs = 3;
    let passes = (0..runs).map(|_| trainer.stage_backward_seconds(batch)).collect::<Result<Vec<_>, _>>()?;
    println!("stages run alone, median of {runs} passes (the step's graph without its loss):");
    println!("| stage | calls | forward (s) | backward (s) | share of the stages' backward | cores busy in backward |");
    println!("|---|---:|---:|---:|---:|---:|");
    let stage =
        |i: usize, f: fn(&StageBackward) -> f64| median(&mut passes.iter().map(|p| f(&p[i])).collect::<Vec<_>>());
    let backward: Vec<f64> = (0..passes[0].len()).map(|i| stage(i, |s| s.backward_seconds)).collect();
    let total: f64 = backward.iter().sum();
    for (i, s) in passes[0].iter().enumerate() {
        let busy = stage(i, |s| s.backward_cpu_seconds / s.backward_seconds);
        let busy = if busy.is_finite() { format!("{busy:.2}") } else { "-".into() };
        println!(
            "| {} | {} | {:.3} | {:.3} | {:.0} % | {busy} |",
            s.name,
            s.calls,
            stage(i, |s| s.forward_seconds),
            backward[i],
            100.0 * backward[i] / total
        );
    }
    println!("| all stages | | | {total:.3} | 100 % |");
    println!("the whole step's backward (median above): {step_backward:.3} s");
    Ok(())
}
