//! The model options shared by `infer`, `eval` and `demo` ([`ModelArgs`]) and what they build
//! ([`load_engine`]): the inference crate's [`Engine`] and the [`PredictOptions`] the command
//! line chose, which each command passes to [`Engine::predict`].
//!
//! The flags map one to one onto [`EngineConfig`] and [`PredictOptions`]; an experiment file
//! (`--experiment`, `--run`) gives the model and prior configurations, and `--prior` /
//! `--prior-weights` override its prior. The library's errors name option fields (an invalid
//! option is a configuration error keyed by its field, `min_size`); [`with_flags`] names the
//! flag that sets it instead (`--min-size`), from one explicit table of fields and flags.
//!
//! Design decision: every whole-run problem (weights that do not load or do not match the
//! experiment, a prior that cannot be built, a device that does not exist) is found by
//! [`load_engine`], once, before any pair is read, so `infer` can fail fast on those and keep
//! going on per-pair ones.

use std::path::PathBuf;

use clap::Args;
use dgstereo_core::DeviceChoice;
use dgstereo_core::device::Precision;
use dgstereo_inference::{CorrChoice, Engine, EngineConfig, MinSize, ModelChoice, PredictOptions, parse_byte_size};

/// The threshold of `--lr-check` given without a value, in pixels
/// ([`dgstereo_inference::consistency::DEFAULT_THRESHOLD`], as clap takes a default).
pub const DEFAULT_LR_CHECK: &str = "2";

/// Update iterations when neither `--iters` nor a checkpoint's preset gives them (the official
/// `--valid_iters`).
pub const DEFAULT_ITERS: usize = 32;

/// Model options shared by `infer` and `eval`.
#[derive(Args, Clone, Debug)]
pub struct ModelArgs {
    /// Weights: a dgstereo `.safetensors`, an official RAFT-Stereo or DEFOM-Stereo `.pth`, or
    /// the name of an official checkpoint (`raftstereo-middlebury`, `defomstereo-vits-sceneflow`;
    /// `dgstereo weights list`), fetched on first use (default: the project's default model).
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
    /// Depth Anything V2 weights (`depth_anything_v2_vit{s,b,l}.pth`, or a name:
    /// `depth-anything-v2-small`, `-base`, `-large`, fetched on first use) for the prior: the same as
    /// `--prior depth-anything-v2:WEIGHTS`, or the weights of the experiment's Depth Anything prior.
    #[arg(long, conflicts_with = "prior")]
    pub prior_weights: Option<PathBuf>,
    /// Device: `cpu` or `gpu` (the GPU needs a build with `--features gpu`).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Float precision of the network: `f32`; on the CPU `bf16`: f32 activations with the
    /// convolutions' products in bf16 (f32 sums) on the processor's AMX tiles or AVX512-BF16;
    /// on the GPU `f16` / `bf16` (weights cast after loading, the whole pass in half precision,
    /// not with a depth prior; `f16` on the CPU runs burn's operations, slowly).
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
    /// Memory allowed for the materialised cost volume, e.g. `4GiB`, `512MiB` (`--corr auto`);
    /// IGEV-Stereo's geometry volume, which has no on-the-fly form, refuses inputs over it.
    #[arg(long, default_value = "4GiB")]
    pub memory_budget: String,
    /// Cost volume implementation.
    #[arg(long, value_enum, default_value_t = CorrChoice::Auto)]
    pub corr: CorrChoice,
    /// Left-right consistency check: also run the mirrored pair for the right view's disparity,
    /// and replace the pixels where the two disagree by more than PX pixels (2 when no value is
    /// given; occlusions, mostly) with their row's nearest confirmed background. Doubles the time;
    /// `--save rejected` writes which pixels were replaced.
    #[arg(long, value_name = "PX", num_args = 0..=1, default_missing_value = DEFAULT_LR_CHECK)]
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

/// An error and its causes on one line ([`dgstereo_inference::error_chain`]), line breaks
/// included.
pub fn error_line(e: &anyhow::Error) -> String {
    dgstereo_inference::error_chain(e.as_ref()).replace(['\n', '\r'], " ")
}

/// The option fields the library's errors name, and the flags that set them, written out one
/// by one (a flag is not always its field's name: `run` is set by `--run NAME`).
const FLAGS: [(&str, &str); 14] = [
    ("iters", "--iters"),
    ("run", "--run NAME"),
    ("max_size", "--max-size"),
    ("min_size", "--min-size"),
    ("memory_budget", "--memory-budget"),
    ("corr", "--corr"),
    ("lr_check", "--lr-check"),
    ("weights", "--weights"),
    ("prior", "--prior"),
    ("device", "--device"),
    ("precision", "--precision"),
    ("calib_crop", "--calib-crop X,Y"),
    ("calib_scale", "--calib-scale S"),
    ("calib", "--calib FILE"),
];

/// The flag that sets the option field `field`.
fn flag(field: &str) -> Option<&'static str> {
    FLAGS.iter().find(|(f, _)| *f == field).map(|(_, flag)| *flag)
}

/// `text` with each option field it quotes (`` `min_size` ``) written as the flag that sets it
/// (`--min-size`).
pub fn flag_names(text: &str) -> String {
    FLAGS.iter().fold(text.to_string(), |m, (field, flag)| m.replace(&format!("`{field}`"), flag))
}

/// The option field and the reason of a library configuration error.
fn config_field(e: &dgstereo_core::Error) -> Option<(&str, &str)> {
    match e {
        dgstereo_core::Error::Config(problem) => Some((problem.key.as_str(), problem.reason.as_str())),
        _ => None,
    }
}

/// A library error on one line as the command line says it: an invalid option names the flag
/// that sets it (`--min-size: ...`), also under what was being done (a pair's names), and every
/// option field quoted in the message is written as its flag.
pub fn with_flags(e: dgstereo_core::Error) -> anyhow::Error {
    anyhow::anyhow!(flag_line(&e).replace(['\n', '\r'], " "))
}

/// [`with_flags`]' line: a context stays before the error it wraps.
fn flag_line(e: &dgstereo_core::Error) -> String {
    if let dgstereo_core::Error::Context { context, source } = e {
        return format!("{}: {}", flag_names(context), flag_line(source));
    }
    let line = match config_field(e).and_then(|(field, reason)| Some((flag(field)?, reason))) {
        Some((flag, reason)) => format!("{flag}: {reason}"),
        None => dgstereo_inference::error_chain(e),
    };
    flag_names(&line)
}

/// The inference crate's [`Engine`] the model flags describe, and the per-pair options they
/// chose (iterations resolved: `--iters`, else a `.pth` checkpoint's preset, else
/// [`DEFAULT_ITERS`]).
pub fn load_engine(a: &ModelArgs) -> anyhow::Result<(Engine, PredictOptions)> {
    let options = PredictOptions {
        iters: a.iters.unwrap_or(DEFAULT_ITERS),
        max_size: a.max_size,
        min_size: a.min_size,
        corr: a.corr,
        lr_check: a.lr_check,
        ..PredictOptions::default()
    };
    // Checked before the weights load.
    options.validate().map_err(with_flags)?;
    let options = PredictOptions { memory_budget: parse_byte_size(&a.memory_budget).map_err(with_flags)?, ..options };
    let device: DeviceChoice = a.device.parse()?;
    let (experiment, run) = (a.experiment.clone(), a.run.clone());
    let choice = ModelChoice { experiment, run, prior: a.prior.clone(), prior_weights: a.prior_weights.clone() };
    let (model, prior) = choice.configs().map_err(with_flags)?;
    // Names of official checkpoints become files (fetched on first use).
    let weights =
        a.weights.as_deref().map(|w| crate::fetching::stereo(w, "weights")).transpose().map_err(with_flags)?;
    let prior = crate::fetching::prior(prior, "prior").map_err(with_flags)?;
    let config = EngineConfig {
        weights,
        model,
        prior,
        device,
        precision: a.precision,
        slow_fast_gru: a.slow_fast_gru,
        bundled_assets: None,
    };
    let engine = Engine::load(&config).map_err(|e| match &a.experiment {
        Some(experiment) => with_flags(e).context(experiment.display().to_string()),
        None => with_flags(e),
    })?;
    for note in engine.notes() {
        eprintln!("note: {}", flag_names(note));
    }
    let iters = a.iters.or(engine.preset_iters()).unwrap_or(DEFAULT_ITERS);
    let options = PredictOptions { iters, ..options };
    engine.check(&options).map_err(with_flags)?;
    Ok((engine, options))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_lines_do_not_repeat_causes() {
        let io = std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "unexpected end of file");
        let e = anyhow::Error::from(dgstereo_core::Error::io("a.png", io)).context("pair a");
        assert_eq!(error_line(&e), "pair a: a.png: unexpected end of file");
    }

    #[test]
    fn library_fields_become_flags() {
        let e = dgstereo_core::Error::config("min_size", "300 is larger than `max_size` 200");
        assert_eq!(with_flags(e).to_string(), "--min-size: 300 is larger than --max-size 200");
        let e = PredictOptions { iters: 0, ..PredictOptions::default() }.validate().unwrap_err();
        assert_eq!(with_flags(e).to_string(), "--iters: must be at least 1");
        assert_eq!(flag_names("the depth prior runs in f32 only"), "the depth prior runs in f32 only");
        assert_eq!(flag("run"), Some("--run NAME"));
        let e = dgstereo_core::Error::config("max_size", "must be at least 32").context("a.png + b.png");
        assert_eq!(with_flags(e).to_string(), "a.png + b.png: --max-size: must be at least 32");
        assert_eq!(DEFAULT_LR_CHECK.parse::<f32>().unwrap(), dgstereo_inference::consistency::DEFAULT_THRESHOLD);
    }

    #[test]
    fn prior_specs_parse() {
        let e = with_flags(dgstereo_inference::parse_prior("magic").unwrap_err()).to_string();
        assert!(e.starts_with("--prior: 'magic': expected none"), "{e}");
    }
}
