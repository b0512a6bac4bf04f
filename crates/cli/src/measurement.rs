//! What the timing commands share (`bench`, `bench --train`, `export`'s sizes): the flags of
//! `bench`, sizes given as `HxW`, the machine line every timing prints, medians, the peak
//! memory, and model configurations read for timing. A module of its own, so that no command
//! module imports another.

use anyhow::Context;
use clap::Args;
use dgstereo_core::device::Precision;
use dgstereo_inference::cost_volume::CorrChoice;
use dgstereo_model::ModelConfig;

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
    /// official RAFT-Stereo or DEFOM-Stereo `.pth` or a checkpoint's name, loaded as
    /// `infer --weights` loads it (the architecture it carries or shows, unless `--config` gives
    /// one).
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
    /// `no-winograd-blocks`, `stock-route=NAME|all` (one GPU formulation off), with
    /// `--precision bf16` `bf16-winograd=off|f2|f4` (which Winograd tiles take bf16 products) and
    /// `no-amx` (AVX512-BF16 where the processor has AMX too).
    #[arg(long, default_value = "host")]
    pub kernels: String,
    /// Precision: `f32`; on the CPU `bf16`: f32 activations with the host kernels' products in
    /// bf16 (f32 sums) on the processor's bf16 unit; on the GPU `f16` / `bf16` for the whole
    /// pass (`f16` on the CPU runs burn's operations).
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
/// mistake: the processor (Linux), the vector level of the products and the unit of bf16
/// products (AMX tiles or AVX512-BF16).
pub fn machine_line() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let bf16 = dgstereo_kernels::bf16_unit().map_or("no bf16 unit".into(), |unit| format!("bf16 on {unit}"));
    format!("machine: {}, {}, {bf16}", cpu_model_name(&cpuinfo).unwrap_or("processor not reported"), vector_level())
}

/// The median of `v` (sorted in place; the mean of the middle two for an even count).
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
        use dgstereo_core::timing::process_cpu_seconds;
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
