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
use clap::Args;
use dgstereo_core::device::Precision;
use dgstereo_core::timing::process_cpu_seconds;
use dgstereo_core::{DepthPrior, DeviceChoice, InputPadder};
use dgstereo_inference::cost_volume::{CorrChoice, DEFAULT_MEMORY_BUDGET, corr_for, corr_name};
use dgstereo_inference::{Engine, EngineConfig};
use dgstereo_kernels::{Op, Path, Settings, count_work, path};
use dgstereo_model::profile::profile_forward;
use dgstereo_model::{ModelConfig, StereoModel};
use dgstereo_prior::{DEFAULT_INPUT_SIZE, PriorConfig, PriorInput, PriorProvider};

use crate::engine::with_flags;

/// Options of `dgstereo bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// Image size `HxW` (padded to a multiple of 32 inside, as `infer` does).
    #[arg(long, default_value = "384x448")]
    pub size: String,
    /// Update iterations.
    #[arg(long, default_value_t = 32)]
    pub iters: usize,
    /// Device: `cpu` or `gpu`.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Timed runs after the warm-up.
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// Untimed warm-up runs.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Cost volume (`auto`: within the 4 GiB that `infer --corr auto` allows by default).
    #[arg(long, value_enum, default_value_t = CorrChoice::Reg)]
    pub corr: CorrChoice,
    /// Model configuration: a TOML file of `ModelConfig`, or an experiment file or model card
    /// (`assets/weights/*.toml`) whose `[model]` is used (default: RAFT-Stereo's, or the one
    /// `--weights` carry).
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Time these weights instead of freshly initialised ones: a dgstereo `.safetensors`, an
    /// official RAFT-Stereo or DEFOM-Stereo `.pth` or a checkpoint's name, loaded as `infer
    /// --weights` loads it (the architecture it carries or shows, unless `--config` gives one).
    #[arg(long)]
    pub weights: Option<std::path::PathBuf>,
    /// Also time each stage of one forward pass (with `--train`: each stage's forward and backward, run alone).
    #[arg(long)]
    pub stages: bool,
    /// The machine's peak GFLOP/s, for the share-of-peak column (2 cores here: ~200).
    #[arg(long, default_value_t = 200.0)]
    pub peak_gflops: f64,
    /// Kernel settings, comma-separated (the words of `DGSTEREO_KERNELS`): `host` (the
    /// hand-written CPU kernels, the default), `stock` (burn's operations only, the reference), to
    /// measure what the kernels gain, `gpu-routes` (burn's operations arranged as GPU inference
    /// arranges them, to check the GPU's composition on a CPU), `no-winograd`,
    /// `no-winograd-blocks`, `stock-route=NAME|all` (one GPU formulation off).
    #[arg(long, default_value = "host")]
    pub kernels: String,
    /// Float precision of the whole forward pass: `f32`, `f16` or `bf16` (the host kernels are
    /// f32-only, so a half precision on the CPU runs burn's operations).
    #[arg(long, default_value = "f32")]
    pub precision: Precision,
    /// Depth Anything V2 weights (`depth_anything_v2_vit{s,b,l}.pth` or a name such as
    /// `depth-anything-v2-small`): every run also computes
    /// the depth prior of both views, as `infer` does, and its time is reported apart (the model
    /// configuration, `--config`, must use a prior). Without it a model with a prior gets a
    /// synthetic one, outside the timed runs.
    #[arg(long)]
    pub prior_weights: Option<std::path::PathBuf>,
    /// Time whole training steps instead of inference (`--iters` iterations, `--size` crops).
    #[arg(long)]
    pub train: bool,
    /// Pairs per training step (`--train`).
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// The experiment whose model, loss and recipe a training step uses (`--train`; default:
    /// the defaults, RAFT-Stereo with the sequence loss).
    #[arg(long)]
    pub experiment: Option<std::path::PathBuf>,
}

/// Parses `HxW`.
pub fn parse_size(s: &str) -> anyhow::Result<[usize; 2]> {
    let (h, w) = s.split_once(['x', 'X']).with_context(|| format!("--size '{s}': expected HxW, e.g. 375x1242"))?;
    let parse = |v: &str, what: &str| {
        v.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| n >= 1)
            .with_context(|| format!("--size '{s}': {what} '{v}' is not a positive integer"))
    };
    Ok([parse(h, "height")?, parse(w, "width")?])
}

/// Peak resident memory of this process in bytes (`VmHWM`), when the OS reports it.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The processor's name from the first `model name` line of a `/proc/cpuinfo` text.
fn cpu_model_name(cpuinfo: &str) -> Option<&str> {
    let line = cpuinfo.lines().find(|l| l.starts_with("model name"))?;
    Some(line.split_once(':')?.1.trim()).filter(|name| !name.is_empty())
}

/// The widest vector instructions the matrix products use on this CPU: the `gemm` crate picks
/// its AVX-512 kernels where the CPU has them (its `x86-v4` feature), else its AVX2/FMA ones,
/// else scalar code; on other architectures, the architecture's name.
fn vector_level() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            "AVX-512"
        } else if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            "AVX2+FMA"
        } else {
            "x86-64 without AVX2"
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::env::consts::ARCH
    }
}

/// One line naming the machine, so that timings from different machines are not compared by
/// mistake: the processor (Linux) and the vector level of the products.
pub fn machine_line() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    format!("machine: {}, {}", cpu_model_name(&cpuinfo).unwrap_or("processor not reported"), vector_level())
}

pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 { v[m] } else { 0.5 * (v[m - 1] + v[m]) }
}

/// `--config`: a `ModelConfig` TOML, or the `[model]` of an experiment file or model card.
pub fn model_config(path: &std::path::Path) -> anyhow::Result<ModelConfig> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let table: toml::Table = toml::from_str(&text).with_context(|| format!("{}: not TOML", path.display()))?;
    if table.contains_key("model") || table.contains_key("base") {
        let (model, _) = dgstereo_inference::experiment_configs(path, None).map_err(with_flags)?;
        return Ok(model);
    }
    toml::from_str::<ModelConfig>(&text).with_context(|| {
        format!("{}: neither a model configuration nor an experiment file with a [model] table", path.display())
    })
}

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
    let precision = a.precision;
    let settings: Settings = a.kernels.parse().with_context(|| format!("--kernels '{}'", a.kernels))?;
    dgstereo_kernels::configure(settings)?;
    // The precision is set before the device's first tensor: burn fixes it there.
    let device = a.device.parse::<DeviceChoice>()?.device_with_precision(precision)?;
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
        let (out, work) =
            count_work(|| model.predict(left.clone(), right.clone(), prior, a.iters, false, Some(implementation)));
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
        "size {h}x{w} (padded {}x{}), {} iterations, {} cost volume, device {}, {precision}, {kernels} kernels, {} threads",
        padded[0],
        padded[1],
        a.iters,
        corr_name(implementation),
        a.device,
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
        let profile = profile_forward(&network, &net_config, pl, pr, pp.as_ref(), a.iters)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_processor_is_named_from_cpuinfo() {
        let cpuinfo = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R) Processor @ 2.50GHz\n\nprocessor\t: 1\nmodel name\t: other\n";
        assert_eq!(cpu_model_name(cpuinfo), Some("Intel(R) Xeon(R) Processor @ 2.50GHz"));
        assert_eq!(cpu_model_name("processor\t: 0\n"), None);
        assert_eq!(cpu_model_name("model name\t:   \n"), None);
        assert!(machine_line().starts_with("machine: "));
    }

    #[test]
    fn sizes_parse_and_bad_ones_are_named() {
        assert_eq!(parse_size("375x1242").unwrap(), [375, 1242]);
        assert_eq!(parse_size("32X64").unwrap(), [32, 64]);
        for bad in ["375", "0x10", "ax10", "10x"] {
            let e = parse_size(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }

    #[test]
    fn median_of_even_and_odd_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
    }

    #[test]
    fn peak_memory_and_cpu_time_are_read_on_linux() {
        if cfg!(all(target_os = "linux", target_env = "gnu")) {
            assert!(peak_memory_bytes().unwrap() > 0);
            let before = process_cpu_seconds().unwrap();
            let mut x = 0u64;
            for i in 0..50_000_000u64 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
            }
            std::hint::black_box(x);
            assert!(process_cpu_seconds().unwrap() >= before);
        }
    }
}
