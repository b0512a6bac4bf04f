//! `dgstereo export onnx`: a loaded model as an ONNX file ([`dgstereo_export`]): static shapes,
//! the iterations unrolled, padding and cropping inside the graph.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::bail;
use clap::{Args, Subcommand};
use dgstereo_inference::{Engine, EngineConfig, experiment_configs};

use crate::engine::{DEFAULT_ITERS, with_flags};
use crate::measurement::parse_size;

/// The `export` subcommands.
#[derive(Subcommand)]
pub enum ExportCommand {
    /// Writes the model as an ONNX file (opset 19) that ONNX Runtime and TensorRT run.
    Onnx(OnnxArgs),
}

/// What `export onnx` exports.
#[derive(Args)]
pub struct OnnxArgs {
    /// Weights: a dgstereo `.safetensors`, an official RAFT-Stereo or DEFOM-Stereo `.pth`, or the
    /// name of an official checkpoint (`dgstereo weights list`) (default: the project's default
    /// model).
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Experiment file whose model configuration the weights were trained with.
    #[arg(long)]
    experiment: Option<PathBuf>,
    /// The run of a sweep experiment to use.
    #[arg(long, requires = "experiment")]
    run: Option<String>,
    /// The pair size the file takes, `HxW` (static: export one file per size).
    #[arg(long)]
    size: String,
    /// Update iterations, unrolled (default: the official preset of a `.pth` checkpoint's
    /// architecture, 7 for the realtime model, else 32).
    #[arg(long)]
    iters: Option<usize>,
    /// Slow-fast GRU schedule, `true` or `false` (default: the experiment's or the preset's).
    #[arg(long)]
    slow_fast_gru: Option<bool>,
    /// Symbolic height and width: not offered (see the message).
    #[arg(long)]
    dynamic: bool,
    /// The file to write.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(cmd: ExportCommand) -> anyhow::Result<ExitCode> {
    let ExportCommand::Onnx(a) = cmd;
    if a.dynamic {
        bail!(
            "--dynamic: not offered. The graph's shapes come from one recording at --size, and the \
             network's pyramid sizes, padding and crop are baked into it as constants; TensorRT wants \
             static shapes anyway. Export one file per input size"
        );
    }
    let [height, width] = parse_size(&a.size)?;
    let model = match &a.experiment {
        Some(p) => Some(experiment_configs(p, a.run.as_deref()).map_err(with_flags)?.0),
        None => None,
    };
    let weights =
        a.weights.as_deref().map(|w| crate::fetching::stereo(w, "weights")).transpose().map_err(with_flags)?;
    let config = EngineConfig { weights, model, slow_fast_gru: a.slow_fast_gru, ..EngineConfig::default() };
    // The prior maps are inputs of the file: the model loads without its provider.
    let engine = Engine::load_with_given_priors(&config).map_err(with_flags)?;
    let iters = a.iters.or(engine.preset_iters()).unwrap_or(DEFAULT_ITERS);
    eprintln!(
        "exporting {} ({}) at {height}x{width}, {iters} iterations",
        engine.weights().display(),
        engine.configuration_summary()
    );
    let start = Instant::now();
    let exported = dgstereo_export::export_onnx(engine.stereo_model(), height, width, iters)?;
    exported.write(&a.output)?;
    let shapes = |v: &[(String, Vec<usize>)]| {
        v.iter()
            .map(|(n, s)| format!("{n} {}", s.iter().map(usize::to_string).collect::<Vec<_>>().join("x")))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!("wrote {} in {:.1} s", a.output.display(), start.elapsed().as_secs_f64());
    println!("opset {}, {} nodes, {:.1} MB", dgstereo_export::OPSET, exported.nodes, exported.bytes.len() as f64 / 1e6);
    let inputs = if engine.model_config().needs_prior() {
        "float32, RGB 0..255; prior maps: relative inverse depth"
    } else {
        "float32, RGB 0..255"
    };
    println!("inputs: {} ({inputs})", shapes(&exported.inputs));
    println!("outputs: {} (float32, positive disparity in pixels)", shapes(&exported.outputs));
    Ok(ExitCode::SUCCESS)
}
