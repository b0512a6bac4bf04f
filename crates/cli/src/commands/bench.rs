//! `dgstereo bench`: timing of whole inference, and optionally of each stage.
//!
//! Design decision: the whole-inference figure goes through [`StereoModel::predict`], the same
//! call `infer` makes (padding, network, cropping), on synthetic images of the requested size,
//! so it measures what a user waits for; the weights are freshly initialised because the cost
//! of the network does not depend on their values. The achieved GFLOP/s divides the
//! multiply-accumulates the network's operations counted as they ran
//! ([`dgstereo_kernels::count_work`]: convolutions and matrix products) by the median time; the
//! count is that of direct convolutions, so where the host path computes
//! a 3x3 convolution by Winograd's algorithm (fewer multiplications) the rate is an effective
//! one, and can exceed what the arithmetic units do. `--stages` adds a per-stage table
//! ([`dgstereo_model::profile::profile_forward`]) with each stage's share of the machine's peak.
//! `--precision f16|bf16` makes that dtype the device's default before anything is created
//! ([`DeviceChoice::device_with_precision`]), so weights, inputs and every activation of the
//! forward pass are half precision (what GPU tensor cores multiply); on the CPU the f32-only
//! host kernels then stand aside for burn's operations.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, bail};
use burn::tensor::{Distribution, Tensor};
use dgstereo_core::device::Precision;
use dgstereo_core::timing::process_cpu_seconds;
use dgstereo_core::{DepthPrior, DeviceChoice, InputPadder};
use dgstereo_inference::cost_volume::{DEFAULT_MEMORY_BUDGET, corr_for, corr_name};
use dgstereo_inference::options::{precision_name, split_precision};
use dgstereo_inference::{Engine, EngineConfig};
use dgstereo_kernels::{Op, Path, Settings, count_work, path, with_products};
use dgstereo_model::profile::profile_forward;
use dgstereo_model::{ModelConfig, StereoModel};
use dgstereo_prior::{DEFAULT_INPUT_SIZE, PriorConfig, PriorInput, PriorProvider};

use crate::engine::with_flags;
use crate::measurement::{BenchArgs, machine_line, median, model_config, parse_size, peak_memory_bytes};

/// The model `bench` times: `--weights` loaded as `infer` loads them, else a fresh network of
/// `--config` (the cost does not depend on the weights' values).
fn bench_model(a: &BenchArgs, device: &burn::tensor::Device) -> anyhow::Result<(StereoModel, ModelConfig)> {
    let config = a.config.as_deref().map(model_config).transpose()?;
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
    let image = || Tensor::<4>::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let (left, right) = (image(), image());
    let prior = config.needs_prior().then(|| DepthPrior {
        left: Tensor::random([1, 1, h, w], Distribution::Uniform(0.1, 1.0), &device),
        right: Tensor::random([1, 1, h, w], Distribution::Uniform(0.1, 1.0), &device),
    });
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
    let mut prior_seconds = Vec::new();
    let padder = InputPadder::new(h, w, config.pad_divisor());
    let padded = padder.padded();
    // The network's work, counted by its operations in each run (the prior's are outside).
    let mut macs = 0;
    // What runs: the host kernels only on f32 CPU inference, whatever `--kernels` asked.
    let kernels = match path(&device, Op::Conv) {
        Path::Host => "host",
        Path::Gpu if device == burn::tensor::Device::flex() => "gpu-routes",
        Path::Gpu => "gpu-formulation",
        Path::Stock if a.kernels.contains("host") => "stock (host kernels inactive)",
        Path::Stock => "stock",
    };

    let mut non_finite = 0;
    let mut predict = || -> anyhow::Result<(f64, f64)> {
        let cpu = process_cpu_seconds();
        // As `infer` does before each pair (outside the timed span): every run has one size, so
        // the passes reuse each other's freed buffers.
        dgstereo_kernels::allocator::release_before_pass([h, w]);
        let start = Instant::now();
        let computed = match &provider {
            Some(p) => {
                let input = PriorInput {
                    left: left.clone(),
                    right: right.clone(),
                    gt_disparity: None,
                    names: vec!["bench".into()],
                };
                let computed = p.provide(&input)?;
                prior_seconds.push(start.elapsed().as_secs_f64());
                computed
            }
            None => None,
        };
        let prior = computed.as_ref().or(prior.as_ref());
        let (out, work) = with_products(products, || {
            count_work(|| model.predict(left.clone(), right.clone(), prior, a.iters, false, Some(implementation)))
        });
        let out = out?;
        macs = work.macs;
        let data = out.last().into_data(); // waits for asynchronous backends
        let wall = start.elapsed().as_secs_f64();
        let cpu = process_cpu_seconds().zip(cpu).map_or(f64::NAN, |(b, a)| b - a);
        // Outside both timed spans: a narrow precision that overflowed times a meaningless map.
        non_finite = data.convert::<f32>().iter::<f32>().filter(|v| !v.is_finite()).count();
        Ok((wall, cpu))
    };
    for _ in 0..a.warmup {
        predict()?;
    }
    let runs = (0..a.runs).map(|_| predict()).collect::<anyhow::Result<Vec<(f64, f64)>>>()?;
    if non_finite > 0 {
        bail!(
            "the disparity has {non_finite} non-finite values in {precision}: the forward pass overflowed, so its time means nothing"
        );
    }
    let mut times: Vec<f64> = runs.iter().map(|r| r.0).collect();
    let mut cpu: Vec<f64> = runs.iter().map(|r| r.1).collect();
    // The warm-up's priors come first; the timed runs' are the last `runs`.
    let mut timed_priors = prior_seconds.split_off(prior_seconds.len().saturating_sub(a.runs));
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
        let (pl, pr) = (padder.pad(left.clone()), padder.pad(right.clone()));
        let pp =
            prior.as_ref().map(|p| DepthPrior { left: padder.pad(p.left.clone()), right: padder.pad(p.right.clone()) });
        let mut net_config = config.clone();
        net_config.correlation.implementation = implementation;
        let mut network = model.network.clone();
        network.correlation.implementation = implementation;
        let profile = with_products(products, || profile_forward(&network, &net_config, pl, pr, pp.as_ref(), a.iters))?;
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
