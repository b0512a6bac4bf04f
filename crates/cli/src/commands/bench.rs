//! `dgstereo bench`: timing of whole inference ([`dgstereo_inference::timing`]: the call `infer`
//! makes, on random images of the requested size), and optionally of each stage. The weights are
//! fresh unless `--weights` gives some: the cost does not depend on their values. The GFLOP/s
//! divide the multiply-accumulates the network's operations counted as they ran by the median
//! time; the count is that of direct convolutions, so where the host path computes a 3x3
//! convolution by Winograd's algorithm the rate is an effective one, and can exceed what the
//! arithmetic units do. `--stages` adds a per-stage table
//! ([`dgstereo_model::profile::profile_forward`]) with each stage's share of the machine's peak.
//! `--precision f16|bf16` makes that dtype the device's default before anything is created
//! ([`DeviceChoice::device_with_precision`]), so weights, inputs and every activation are half
//! precision; on the CPU the f32-only host kernels then stand aside for burn's operations.

use std::process::ExitCode;

use anyhow::{Context, bail};
use dgstereo_core::DeviceChoice;
use dgstereo_core::device::Precision;
use dgstereo_core::timing::{median, peak_memory_bytes};
use dgstereo_inference::cost_volume::{DEFAULT_MEMORY_BUDGET, corr_for, corr_name};
use dgstereo_inference::options::{precision_name, split_precision};
use dgstereo_inference::timing::TimedInference;
use dgstereo_inference::{Engine, EngineConfig, model_config_file};
use dgstereo_kernels::{Op, Path, Settings, machine_line, path};
use dgstereo_model::{ModelConfig, StereoModel};
use dgstereo_prior::{DEFAULT_INPUT_SIZE, PriorConfig};

use crate::engine::with_flags;
use crate::measurement::{BenchArgs, parse_size};

/// The model `bench` times: `--weights` loaded as `infer` loads them, else a fresh network of
/// `--config` (the cost does not depend on the weights' values).
fn bench_model(a: &BenchArgs, device: &burn::tensor::Device) -> anyhow::Result<(StereoModel, ModelConfig)> {
    let config = a.config.as_deref().map(|p| model_config_file(p).map_err(with_flags)).transpose()?;
    let Some(weights) = &a.weights else {
        let config = config.unwrap_or_default();
        return Ok((StereoModel::new(config.init(device)?, config.clone(), device.clone()), config));
    };
    // A checkpoint's name becomes its file (fetched on first use), as for `infer`.
    let weights = crate::fetching::stereo(weights, "weights").map_err(with_flags)?;
    let engine = Engine::load_with_given_priors(&EngineConfig {
        weights: Some(weights),
        model: config,
        device: a.device.parse()?,
        precision: a.precision,
        ..EngineConfig::default()
    })
    .map_err(with_flags)?;
    eprintln!("weights {} ({})", engine.weights().display(), engine.configuration_summary());
    let (network, config) = (engine.stereo_model().network.clone(), engine.model_config().clone());
    Ok((StereoModel::new(network, config.clone(), engine.device().clone()), config))
}

pub fn run(a: BenchArgs) -> anyhow::Result<ExitCode> {
    let [h, w] = parse_size(&a.size)?;
    if a.iters == 0 {
        bail!("--iters must be at least 1");
    }
    if a.runs == 0 {
        bail!("--runs must be at least 1");
    }
    let settings: Settings = a.kernels.parse().with_context(|| format!("--kernels '{}'", a.kernels))?;
    dgstereo_kernels::configure(settings)?;
    let device_choice = a.device.parse::<DeviceChoice>()?;
    let (precision, products) = split_precision(device_choice, a.precision);
    // The precision is set before the device's first tensor: burn fixes it there.
    let device = device_choice.device_with_precision(precision)?;
    let (model, config) = bench_model(&a, &device)?;
    let implementation = corr_for(&config, a.corr, DEFAULT_MEMORY_BUDGET, w, h);
    let provider = match &a.prior_weights {
        Some(_) if precision != Precision::F32 => {
            bail!("--precision {precision}: the depth prior runs in f32 only; leave out --precision or --prior-weights")
        }
        Some(_) if !config.needs_prior() => {
            bail!(
                "--prior-weights: this model configuration uses no depth prior (pass --config of a model with fusion or guidance)"
            )
        }
        Some(weights) => Some(
            crate::fetching::prior(
                PriorConfig::DepthAnythingV2 {
                    weights: weights.clone(),
                    encoder: None,
                    input_size: DEFAULT_INPUT_SIZE,
                },
                "prior_weights",
            )
            .and_then(|prior| prior.init(&device))
            .with_context(|| format!("--prior-weights {}", weights.display()))?,
        ),
        None => None,
    };
    // What runs: the host kernels only on f32 CPU inference, whatever `--kernels` asked.
    let kernels = match path(&device, Op::Conv) {
        Path::Host => "host",
        Path::Gpu if device == burn::tensor::Device::flex() => "gpu-routes",
        Path::Gpu => "gpu-formulation",
        Path::Stock if a.kernels.contains("host") => "stock (host kernels inactive)",
        Path::Stock => "stock",
    };

    let timed = TimedInference::new(&model, [h, w], a.iters, implementation, products, provider.as_ref());
    let padded = timed.padded();
    let timing = timed.time(a.warmup, a.runs)?;
    let (runs, macs, non_finite) = (&timing.runs, timing.macs, timing.non_finite);
    if non_finite > 0 {
        bail!(
            "the disparity has {non_finite} non-finite values in {precision}: the forward pass overflowed, so its time means nothing"
        );
    }
    let mut times: Vec<f64> = runs.iter().map(|r| r.wall).collect();
    let mut cpu: Vec<f64> = runs.iter().map(|r| r.cpu).collect();
    let mut timed_priors: Vec<f64> = runs.iter().filter_map(|r| r.prior).collect();
    // The operation count is the stereo network's: with a timed prior its rate is over the
    // network's share of each run.
    let mut network: Vec<f64> =
        times.iter().zip(timed_priors.iter().chain(std::iter::repeat(&0.0))).map(|(t, p)| t - p).collect();
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    let med = median(&mut times);
    let gflops = 2.0 * macs as f64 / median(&mut network) / 1e9;
    println!(
        "size {h}x{w} (padded {}x{}), {} iterations, {} cost volume, device {}, {}, {kernels} kernels, {} threads",
        padded[0],
        padded[1],
        a.iters,
        corr_name(implementation),
        a.device,
        precision_name(precision, products),
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
    );
    println!("model: {}", dgstereo_model::checkpoint_config::summary(&config));
    println!("{}", machine_line());
    println!("runs {} after {} warm-up: median {med:.3} s, min {min:.3} s", a.runs, a.warmup);
    println!("CPU time per run (all threads): median {:.2} s", median(&mut cpu));
    if !timed_priors.is_empty() {
        println!(
            "of which the depth prior (Depth Anything V2, both views): median {:.3} s; the GFLOP/s below are the network's",
            median(&mut timed_priors)
        );
    }
    println!("throughput {:.3} megapixels/s", (h * w) as f64 / 1e6 / med);
    println!(
        "work {:.1} GFLOP (direct convolutions): {gflops:.1} GFLOP/s effective ({:.0} % of a {:.0} GFLOP/s peak)",
        2.0 * macs as f64 / 1e9,
        100.0 * gflops / a.peak_gflops,
        a.peak_gflops
    );

    if a.stages {
        let profile = timed.stages()?;
        let total = profile.total_seconds();
        println!();
        println!("| stage | calls | time (s) | share of time | cores busy | GFLOP/s | share of peak |");
        println!("|---|---:|---:|---:|---:|---:|---:|");
        for s in &profile.stages {
            let (gf, peak) = match s.gflops() {
                Some(g) => (format!("{g:.1}"), format!("{:.0} %", 100.0 * g / a.peak_gflops)),
                None => ("-".into(), "-".into()),
            };
            let busy = s.cores_busy().map_or("-".into(), |b| format!("{b:.2}"));
            println!(
                "| {} | {} | {:.3} | {:.1} % | {busy} | {gf} | {peak} |",
                s.name,
                s.calls,
                s.seconds,
                100.0 * s.seconds / total
            );
        }
        let cpu: f64 = profile.stages.iter().map(|s| s.cpu_seconds).sum();
        let busy = if cpu.is_finite() && total > 0.0 { format!("{:.2}", cpu / total) } else { "-".into() };
        println!("| total | | {total:.3} | 100 % | {busy} | | |");
    }
    match peak_memory_bytes() {
        Some(b) => println!("peak memory (VmHWM, whole process) {:.0} MiB", b as f64 / (1024.0 * 1024.0)),
        None => println!("peak memory: not reported by this OS"),
    }
    Ok(ExitCode::SUCCESS)
}
