//! Running a model on one stereo pair as a user asks: the options shared by `infer` and `eval`
//! ([`ModelArgs`]) and the [`Engine`] they build.
//!
//! The engine owns the network, the prior provider and the per-pair policy:
//! - `--max-size N` downscales both views so the longer side is at most `N` pixels, and
//!   `--min-size` (default `auto`) upscales small pairs for 1/8-resolution models
//!   ([`crate::working_size`]); the disparity is resized back to the input size and multiplied
//!   by the inverse scale;
//! - the cost volume is the materialised pyramid ("reg", fast) unless its estimated size
//!   ([`CorrelationConfig::pyramid_bytes`] at the padded feature resolution) exceeds
//!   `--memory-budget`, then the on-the-fly volume ("alt", memory linear in the width) is used;
//!   `--corr reg|alt` forces one;
//! - `--lr-check` also runs the mirrored pair and fills the pixels the right view does not
//!   confirm ([`crate::consistency`]).
//!
//! Design decision: every whole-run problem (weights that do not load or do not match the
//! experiment, a prior that cannot be built, a device that does not exist) is found here, once,
//! before any pair is read, so `infer` can fail fast on those and keep going on per-pair ones.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use burn::tensor::Device;
use clap::{Args, ValueEnum};
use dgstereo_core::DeviceChoice;
use dgstereo_core::device::Precision;
use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_data::resize::{disparity_to_size, resize_rgb};
use dgstereo_data::{DisparityMap, Mask, RgbImage};
use dgstereo_model::checkpoint_config::summary;
use dgstereo_model::{ModelConfig, StereoModel};
use dgstereo_prior::{Prior, PriorConfig, PriorInput, PriorProvider};

use crate::consistency::{self, fill_rejected, mirror_disparity, mirror_rgb, rejected_pixels};
use crate::convert::{disparity_map, image_tensor};
use crate::models::{default_weights, load_model};
use crate::working_size::{MinSize, working_scale};

/// Which cost volume to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CorrChoice {
    /// "reg" unless it would exceed `--memory-budget`, then "alt".
    Auto,
    /// Always the materialised pyramid.
    Reg,
    /// Always on-the-fly correlation.
    Alt,
}

/// Update iterations when neither `--iters` nor a checkpoint's preset gives them (the official
/// `--valid_iters`).
pub const DEFAULT_ITERS: usize = 32;

/// Model options shared by `infer` and `eval`.
#[derive(Args, Clone, Debug)]
pub struct ModelArgs {
    /// Weights: a dgstereo `.safetensors` or an official RAFT-Stereo `.pth` (default: the
    /// project's default model).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Experiment file whose model (and prior) configuration the weights were trained with.
    #[arg(long)]
    pub experiment: Option<PathBuf>,
    /// The run of a sweep experiment to use (its name as `dgstereo experiment` lists it).
    #[arg(long, requires = "experiment")]
    pub run: Option<String>,
    /// Update iterations (default: the official preset of a `.pth` checkpoint's architecture,
    /// 7 for the realtime model, else 32).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Slow-fast GRU schedule, `true` or `false` (default: the experiment's, or the official
    /// preset of a `.pth` checkpoint's architecture: on for the realtime model).
    #[arg(long)]
    pub slow_fast_gru: Option<bool>,
    /// Depth prior: `none`, `file:DIR` (precomputed `{name}_left`/`{name}_right` maps) or
    /// `depth-anything-v2:WEIGHTS` (default: the experiment's `[prior]`, else none).
    #[arg(long)]
    pub prior: Option<String>,
    /// Depth Anything V2 weights (`depth_anything_v2_vit{s,b,l}.pth`) for the prior: the same as
    /// `--prior depth-anything-v2:WEIGHTS`, or the weights of the experiment's Depth Anything prior.
    #[arg(long, conflicts_with = "prior")]
    pub prior_weights: Option<PathBuf>,
    /// Device: `cpu` or `gpu` (the GPU needs a build with `--features gpu`).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Float precision of the network: `f32`, or `f16` / `bf16` (weights cast after loading;
    /// for GPUs, whose tensor cores multiply half precision; slower on the CPU, where the
    /// hand-written f32 kernels stand aside). Not with a depth prior.
    #[arg(long, default_value = "f32")]
    pub precision: Precision,
    /// Downscale pairs whose longer side exceeds this many pixels (disparity is rescaled back).
    #[arg(long)]
    pub max_size: Option<usize>,
    /// Upscale pairs whose longer side is under this many pixels (disparity is rescaled back):
    /// `auto` (900 for models at 1/8 resolution such as the bundled default, which lose fine
    /// structure on small pairs; off for 1/4-resolution models and with --max-size), `off`, or pixels.
    #[arg(long, default_value = "auto")]
    pub min_size: MinSize,
    /// Memory allowed for the materialised cost volume, e.g. `4GiB`, `512MiB` (`--corr auto`).
    #[arg(long, default_value = "4GiB")]
    pub memory_budget: String,
    /// Cost volume implementation.
    #[arg(long, value_enum, default_value_t = CorrChoice::Auto)]
    pub corr: CorrChoice,
    /// Left-right consistency check: also run the mirrored pair for the right view's disparity,
    /// and replace the pixels where the two disagree by more than PX pixels (2 when no value is
    /// given; occlusions, mostly) with their row's nearest confirmed background. Doubles the time;
    /// `--save rejected` writes which pixels were replaced.
    #[arg(long, value_name = "PX", num_args = 0..=1, default_missing_value = consistency::DEFAULT_THRESHOLD)]
    pub lr_check: Option<f32>,
}

impl ModelArgs {
    /// The options as the command line gives them without any flag (clap's defaults, declared
    /// once on the fields above), for commands that fix some of them.
    pub fn defaults() -> Self {
        #[derive(clap::Parser)]
        struct Only {
            #[command(flatten)]
            args: ModelArgs,
        }
        <Only as clap::Parser>::parse_from(["dgstereo"]).args
    }
}

/// An error and its causes on one line, without repeating a cause its parent already quotes
/// (the library errors embed their I/O cause in their own message).
pub fn error_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line.replace(['\n', '\r'], " ")
}

/// Parses a byte size: a number with an optional `B`, `KB`/`KiB`, `MB`/`MiB`, `GB`/`GiB`, `TB`/`TiB`.
pub fn parse_bytes(s: &str) -> anyhow::Result<u64> {
    let t = s.trim();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let value: f64 = num.parse().with_context(|| format!("--memory-budget '{s}': not a size like 4GiB"))?;
    let mult: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "kib" => 1024.0,
        "m" | "mb" => 1e6,
        "mib" => 1024f64.powi(2),
        "g" | "gb" => 1e9,
        "gib" => 1024f64.powi(3),
        "t" | "tb" => 1e12,
        "tib" => 1024f64.powi(4),
        other => bail!("--memory-budget '{s}': unknown unit '{other}' (use B, MiB, GiB, ...)"),
    };
    Ok((value * mult) as u64)
}

/// Parses `--prior`: `none`, `file:DIR`, `depth-anything-v2:WEIGHTS` (also `dav2:WEIGHTS`).
pub fn parse_prior(spec: &str) -> anyhow::Result<PriorConfig> {
    let (kind, arg) = spec.split_once(':').unwrap_or((spec, ""));
    Ok(match (kind.to_ascii_lowercase().as_str(), arg) {
        ("none", _) => PriorConfig::None,
        ("file", dir) if !dir.is_empty() => PriorConfig::File {
            dir: dir.into(),
            left: dgstereo_prior::file::DEFAULT_LEFT_PATTERN.into(),
            right: dgstereo_prior::file::DEFAULT_RIGHT_PATTERN.into(),
        },
        ("depth-anything-v2" | "dav2", w) if !w.is_empty() => {
            PriorConfig::DepthAnythingV2 { weights: w.into(), encoder: None, input_size: 518 }
        }
        _ => bail!("--prior '{spec}': expected none, file:DIR or depth-anything-v2:WEIGHTS"),
    })
}

/// `--prior-weights`: the experiment's Depth Anything V2 prior (kept inside a cache) with these
/// weights, or a plain Depth Anything V2 prior when the experiment names none.
fn with_prior_weights(config: PriorConfig, weights: &std::path::Path) -> PriorConfig {
    match config {
        PriorConfig::DepthAnythingV2 { encoder, input_size, .. } => {
            PriorConfig::DepthAnythingV2 { weights: weights.to_path_buf(), encoder, input_size }
        }
        PriorConfig::Cache { dir, inner } => {
            PriorConfig::Cache { dir, inner: Box::new(with_prior_weights(*inner, weights)) }
        }
        _ => PriorConfig::DepthAnythingV2 { weights: weights.to_path_buf(), encoder: None, input_size: 518 },
    }
}

/// The model and prior configurations of an experiment file's run: the only run, or the one
/// named `run` when the file resolves to several (a sweep).
fn experiment_configs(path: &Path, run: Option<&str>) -> anyhow::Result<(ModelConfig, PriorConfig)> {
    let runs = dgstereo_experiment::load(path)?;
    let names = || runs.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ");
    let chosen = match (run, runs.len()) {
        (Some(name), _) => runs
            .iter()
            .find(|r| r.name == name)
            .with_context(|| format!("{}: no run named '{name}' (runs: {})", path.display(), names()))?,
        (None, 1) => &runs[0],
        (None, 0) => bail!("{}: the experiment defines no run", path.display()),
        (None, _) => {
            bail!("{}: the experiment has {} runs; pick one with --run NAME ({})", path.display(), runs.len(), names())
        }
    };
    Ok((chosen.config.model.clone(), chosen.config.prior.clone()))
}

/// The cost volume `choice` gives for a `width x height` input of a model of `config`: with
/// [`CorrChoice::Auto`], "alt" when the materialised pyramid of the padded input's features
/// would take more than `budget` bytes.
pub fn corr_for(
    config: &ModelConfig,
    choice: CorrChoice,
    budget: u64,
    width: usize,
    height: usize,
) -> CorrelationImplementation {
    match choice {
        CorrChoice::Reg => CorrelationImplementation::Reg,
        CorrChoice::Alt => CorrelationImplementation::Alt,
        CorrChoice::Auto => {
            let pad = |v: usize| v.div_ceil(32) * 32;
            let f = config.factor();
            let bytes = config.correlation.pyramid_bytes(1, pad(height) / f, pad(width) / f);
            if bytes as u64 > budget { CorrelationImplementation::Alt } else { CorrelationImplementation::Reg }
        }
    }
}

/// What happened on one pair.
#[derive(Clone, Debug, PartialEq)]
pub struct RunInfo {
    /// Size the network saw (after `--max-size` / `--min-size`).
    pub network_size: (usize, usize),
    /// Cost volume used.
    pub corr: CorrelationImplementation,
    /// With `--lr-check`: the pixels the right view did not confirm (row-major, at the input's
    /// size), which the returned disparity has filled.
    pub rejected: Option<Mask>,
    /// Seconds spent computing the depth prior (both passes with `--lr-check`); `None` without
    /// a prior.
    pub prior_seconds: Option<f64>,
}

impl RunInfo {
    /// With `--lr-check`, the share of the pixels it replaced (0 to 1).
    pub fn rejected_share(&self) -> Option<f64> {
        self.rejected.as_ref().map(|m| m.count() as f64 / m.data.len().max(1) as f64)
    }
}

/// A loaded model with its prior and per-pair policy.
pub struct Engine {
    model: StereoModel,
    prior: Option<Prior>,
    /// Update iterations per pair.
    pub iters: usize,
    /// The model configuration chosen, on one line, with where it came from.
    pub configuration: String,
    max_size: Option<usize>,
    /// Pairs whose longer side is under this are upscaled to it (`--min-size`, resolved).
    pub min_size: Option<usize>,
    budget: u64,
    corr: CorrChoice,
    lr_check: Option<f32>,
    /// The weights file.
    pub weights: PathBuf,
    /// The device.
    pub device: Device,
}

impl Engine {
    /// Loads the weights (into the experiment's model when given) and builds the prior.
    pub fn new(a: &ModelArgs) -> anyhow::Result<Self> {
        if a.iters == Some(0) {
            bail!("--iters must be at least 1");
        }
        if a.max_size == Some(0) || a.max_size.is_some_and(|m| m < 32) {
            bail!("--max-size must be at least 32 pixels");
        }
        // An explicit lower bound is checked before the weights load (`auto` never conflicts:
        // it is off with --max-size).
        match (a.min_size, a.max_size) {
            (MinSize::Pixels(lo), Some(hi)) if lo > hi => bail!("--min-size {lo} is larger than --max-size {hi}"),
            (MinSize::Pixels(lo), _) if lo < 32 => bail!("--min-size must be at least 32 pixels (or `off`)"),
            _ => {}
        }
        if let Some(t) = a.lr_check
            && !(t.is_finite() && t > 0.0)
        {
            bail!("--lr-check {t}: the threshold must be a positive number of pixels");
        }
        let budget = parse_bytes(&a.memory_budget)?;
        let choice: DeviceChoice = a.device.parse()?;
        let device = choice.device_with_precision(a.precision)?;
        let (config, experiment_prior) = match &a.experiment {
            Some(p) => {
                let (m, pr) = experiment_configs(p, a.run.as_deref())?;
                (Some(m), pr)
            }
            None => (None, PriorConfig::None),
        };
        let prior_config = match (&a.prior, &a.prior_weights) {
            (Some(spec), _) => parse_prior(spec)?,
            (None, Some(w)) => with_prior_weights(experiment_prior, w),
            (None, None) => experiment_prior,
        };
        if a.precision != Precision::F32 && prior_config.gives_prior() {
            bail!("--precision {}: the depth prior runs in f32 only; leave out --precision or the prior", a.precision);
        }
        let weights = match &a.weights {
            Some(w) => w.clone(),
            None => default_weights(prior_config.gives_prior() && a.experiment.is_none())?,
        };
        let from_experiment = config.is_some();
        let (mut model, detected) = load_model(&weights, config, &device).with_context(|| match &a.experiment {
            Some(e) => format!("weights {} do not fit the model of {}", weights.display(), e.display()),
            None => format!("cannot load weights {}", weights.display()),
        })?;
        if let Some(on) = a.slow_fast_gru {
            model.network.update_block.slow_fast_gru = on;
            model.config.updater.slow_fast_gru = on;
        }
        let iters = a.iters.or(detected.as_ref().map(|d| d.valid_iters)).unwrap_or(DEFAULT_ITERS);
        let source = match (&detected, from_experiment) {
            (Some(d), _) => format!("from the checkpoint's tensors; preset: {}", d.preset.name()),
            (None, true) => "from the experiment".into(),
            (None, false) => "from the weights file".into(),
        };
        let configuration = format!("{}, {iters} iterations ({source})", summary(&model.config));
        let prior = if prior_config.gives_prior() {
            if prior_config.uses_ground_truth() {
                bail!("--prior: a simulated prior needs ground truth and cannot be used for inference");
            }
            if !model.config.needs_prior() {
                eprintln!("note: this model uses no depth prior; --prior is ignored");
                None
            } else {
                Some(prior_config.init(&device).context("--prior")?)
            }
        } else {
            None
        };
        if a.lr_check.is_some() && prior.is_some() && matches!(prior_config, PriorConfig::File { .. }) {
            bail!(
                "--lr-check runs the mirrored pair, and a precomputed (file:) prior has no mirrored views: use a depth-anything-v2 prior or leave out --lr-check"
            );
        }
        if model.config.needs_prior() && prior.is_none() {
            bail!(
                "this model uses a depth prior (fusion or guidance): pass --prior (e.g. depth-anything-v2:WEIGHTS or file:DIR)"
            );
        }
        let min_size = a.min_size.resolve(model.config.factor(), a.max_size);
        Ok(Self {
            model,
            prior,
            iters,
            configuration,
            max_size: a.max_size,
            min_size,
            budget,
            corr: a.corr,
            lr_check: a.lr_check,
            weights,
            device,
        })
    }

    /// The cost volume for a network input of `width x height` (before padding).
    pub fn choose_corr(&self, width: usize, height: usize) -> CorrelationImplementation {
        corr_for(&self.model.config, self.corr, self.budget, width, height)
    }

    /// The disparity of a rectified pair at the left image's size (with `--lr-check`, the pixels
    /// the right view does not confirm filled, and named in [`RunInfo::rejected`]).
    pub fn disparity(&self, left: &RgbImage, right: &RgbImage, name: &str) -> anyhow::Result<(DisparityMap, RunInfo)> {
        if (left.width, left.height) != (right.width, right.height) {
            bail!(
                "left image is {}x{} but right image is {}x{}: a rectified pair has one size",
                left.width,
                left.height,
                right.width,
                right.height
            );
        }
        let (disparity, info) = self.network_disparity(left, right, name)?;
        let Some(threshold) = self.lr_check else {
            return Ok((disparity, info));
        };
        // The right view's disparity is the left one of the mirrored, swapped pair.
        let (mirrored, mirrored_info) = self.network_disparity(&mirror_rgb(right), &mirror_rgb(left), name)?;
        let rejected = rejected_pixels(&disparity, &mirror_disparity(&mirrored), threshold);
        let filled = fill_rejected(&disparity, &rejected);
        let prior_seconds = info.prior_seconds.zip(mirrored_info.prior_seconds).map(|(a, b)| a + b);
        Ok((filled, RunInfo { rejected: Some(rejected), prior_seconds, ..info }))
    }

    /// The network's disparity of a pair of one size, at that size.
    fn network_disparity(
        &self,
        left: &RgbImage,
        right: &RgbImage,
        name: &str,
    ) -> anyhow::Result<(DisparityMap, RunInfo)> {
        let (w, h) = (left.width, left.height);
        let scale = working_scale(w, h, self.min_size, self.max_size);
        let (l, r) = if scale != 1.0 {
            (resize_rgb(left, scale, scale), resize_rgb(right, scale, scale))
        } else {
            (left.clone(), right.clone())
        };
        // The last pass's freed buffers go back to the system where this pass's size differs;
        // a pass of the same size (the next frame, the mirrored pass) reuses them.
        dgstereo_kernels::allocator::release_before_pass([l.height, l.width]);
        let corr = self.choose_corr(l.width, l.height);
        let (lt, rt) = (image_tensor(&l, &self.device), image_tensor(&r, &self.device));
        let prior_start = Instant::now();
        let prior = match &self.prior {
            Some(p) => p.provide(&PriorInput {
                left: lt.clone(),
                right: rt.clone(),
                gt_disparity: None,
                names: vec![name.to_string()],
            })?,
            None => None,
        };
        let prior_seconds = prior.is_some().then(|| prior_start.elapsed().as_secs_f64());
        let pred = self.model.predict(lt, rt, prior.as_ref(), self.iters, false, Some(corr))?;
        let small = disparity_map(pred.last());
        drop(pred);
        let info = RunInfo { network_size: (l.width, l.height), corr, rejected: None, prior_seconds };
        Ok((disparity_to_size(&small, w, h)?, info))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_sizes_parse_with_units() {
        assert_eq!(parse_bytes("4GiB").unwrap(), 4 << 30);
        assert_eq!(parse_bytes("512 MiB").unwrap(), 512 << 20);
        assert_eq!(parse_bytes("1.5kb").unwrap(), 1500);
        assert!(parse_bytes("lots").is_err() && parse_bytes("3 parsecs").is_err());
    }

    #[test]
    fn error_lines_do_not_repeat_causes() {
        let io = std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "unexpected end of file");
        let e = anyhow::Error::from(dgstereo_core::Error::io("a.png", io)).context("pair a");
        assert_eq!(error_line(&e), "pair a: a.png: unexpected end of file");
    }

    #[test]
    fn large_inputs_switch_to_the_on_the_fly_volume() {
        let config = ModelConfig::default();
        // 1024 x 768 at 1/4: 256 x 192 features; rows of 256 + 128 + 64 + 32 + 16 floats each.
        let bytes = 4 * 192 * 256 * (256 + 128 + 64 + 32 + 16);
        assert_eq!(config.correlation.pyramid_bytes(1, 192, 256), bytes);
        let pick = |budget| corr_for(&config, CorrChoice::Auto, budget, 1000, 750);
        assert_eq!(pick(bytes as u64), CorrelationImplementation::Reg);
        assert_eq!(pick(bytes as u64 - 1), CorrelationImplementation::Alt);
        assert_eq!(corr_for(&config, CorrChoice::Reg, 0, 1000, 750), CorrelationImplementation::Reg);
    }

    #[test]
    fn prior_specs_parse() {
        assert_eq!(parse_prior("none").unwrap(), PriorConfig::None);
        assert!(matches!(parse_prior("file:/tmp/p").unwrap(), PriorConfig::File { .. }));
        assert!(matches!(parse_prior("dav2:w.pth").unwrap(), PriorConfig::DepthAnythingV2 { .. }));
        assert!(parse_prior("file:").is_err() && parse_prior("magic").is_err());
    }
}
