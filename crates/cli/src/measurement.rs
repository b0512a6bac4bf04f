//! What the timing commands share (`bench`, `bench --train`, `export`'s sizes): the flags of
//! `bench` and sizes given as `HxW`. A module of its own, so that no command module imports
//! another; the machine line, medians and the peak memory are the libraries'
//! ([`dgstereo_kernels::machine_line`], [`dgstereo_core::timing`]).

use anyhow::Context;
use clap::Args;
use dgstereo_core::device::Precision;
use dgstereo_inference::cost_volume::CorrChoice;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_bad_ones_are_named() {
        assert_eq!(parse_size("375x1242").unwrap(), [375, 1242]);
        assert_eq!(parse_size("32X64").unwrap(), [32, 64]);
        for bad in ["375", "0x10", "ax10", "10x"] {
            let e = parse_size(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }
}
