//! The `dgstereo` command-line tool: it parses flags, calls the library crates and prints.
//!
//! Each subcommand lives in `commands/`; what running a model involves is the inference crate's
//! ([`dgstereo_inference`]: the engine, the pairs' files and outputs, the timing), the pairs a
//! user names and the pictures are the data crate's, the stop signals the signals crate's. Errors
//! are reported as one line naming the file and the problem, with a non-zero exit status, never a
//! panic message.

mod commands;
mod engine;
mod fetching;
mod measurement;
mod sigpipe;
mod train_progress;
mod training;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Deep stereo matching with a monocular depth prior (RAFT-Stereo + DGIA, Gradient-GRU, EALS).
#[derive(Parser)]
#[command(name = "dgstereo", version, about, propagate_version = true)]
struct Cli {
    /// Never download: a weights name missing from the cache is an error (also
    /// `DGSTEREO_OFFLINE=1`).
    #[arg(long, global = true)]
    offline: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Disparity of the bundled Cones pair with the default weights: the quickest look.
    Demo(commands::demo::DemoArgs),
    /// Disparity (and depth, point clouds) of your stereo pairs.
    Infer(commands::infer::InferArgs),
    /// Runs a model over a data set and prints (and writes) a table of metrics.
    Eval(commands::eval::EvalArgs),
    /// Resolves, validates and smoke-tests experiment files.
    #[command(subcommand)]
    Experiment(commands::experiment::ExperimentCommand),
    /// Trains a model from an experiment file.
    Train(commands::train::TrainArgs),
    /// Trains (or reuses) and evaluates every run of experiment files; writes the ablation table.
    Ablate(commands::ablate::AblateArgs),
    /// Times whole inference at a given size: median/min seconds, megapixels/s, GFLOP/s, memory.
    Bench(measurement::BenchArgs),
    /// Scores one disparity prediction against ground truth; prints JSON.
    Metrics(commands::metrics::MetricsArgs),
    /// Compares a model with activations computed by the official PyTorch code.
    #[command(subcommand)]
    Verify(commands::verify::VerifyCommand),
    /// Official checkpoints by name: lists them, fetches them into the cache.
    #[command(subcommand)]
    Weights(commands::weights::WeightsCommand),
    /// Writes a model in another format: `export onnx`.
    #[command(subcommand)]
    Export(commands::export::ExportCommand),
}

fn main() -> ExitCode {
    sigpipe::restore_default_sigpipe();
    let cli = Cli::parse();
    dgstereo_kernels::allocator::retain_freed_memory();
    fetching::set_offline(cli.offline);
    // `bench --kernels` configures the kernels itself; every other command takes
    // `DGSTEREO_KERNELS`, and a malformed value is an error naming the variable and the value,
    // before any work.
    if !matches!(cli.command, Command::Bench(_))
        && let Err(e) = dgstereo_kernels::Settings::from_env().and_then(dgstereo_kernels::configure)
    {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let result = match cli.command {
        Command::Demo(a) => commands::demo::run(a),
        Command::Infer(a) => commands::infer::run(a),
        Command::Eval(a) => commands::eval::run(a),
        Command::Experiment(c) => commands::experiment::run(c),
        Command::Train(a) => commands::train::run(a),
        Command::Ablate(a) => commands::ablate::run(a),
        Command::Bench(a) if a.train => commands::bench_train::run(&a),
        Command::Bench(a) => commands::bench::run(a),
        Command::Metrics(a) => commands::metrics::run(a),
        Command::Verify(c) => commands::verify::run(c),
        Command::Weights(c) => commands::weights::run(c),
        Command::Export(c) => commands::export::run(c),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", engine::error_line(&e));
            ExitCode::FAILURE
        }
    }
}
