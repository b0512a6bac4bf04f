//! `dgstereo experiment`: tools for experiment files.
//!
//! `check` resolves and validates each file (bases, sweeps, defaults), then builds every run's
//! model, counts its trainable parameters and runs one forward pass on a small synthetic pair.
//! Unless `--config-only`, it also opens everything each run reads, the header of every benchmark
//! sample included ([`dgstereo_train::preflight`]). Two runs of one name among the files (they
//! would train into one folder of a study) fail too. It prints one line per run and exits with
//! status 1 when any file or run fails; a failing file does not stop the others from being
//! checked. `samples` writes the training pairs a run draws
//! (after augmentation, exactly as the trainer sees them) as pictures, to look at the data before
//! spending hours on it. `validate` scores weights on a run's held-out synthetic set, the numbers
//! its training log would show, so candidates (and the starting point of a run) compare on the set
//! a ship decision names.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::Subcommand;

use dgstereo_data::visualize::{colorize, display_range, side_by_side};

/// Experiment-file tools.
#[derive(Subcommand)]
pub enum ExperimentCommand {
    /// Resolves and validates files, checks the data, weights and benchmark folders they name,
    /// builds each model and runs one small forward pass.
    Check {
        /// Experiment files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Size `HEIGHTxWIDTH` of the synthetic pair.
        #[arg(long, default_value = "64x96", value_parser = parse_size)]
        size: [usize; 2],
        /// Update iterations of the forward pass.
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..))]
        iters: u16,
        /// Print each run's resolved configuration (TOML) after its line.
        #[arg(long)]
        show: bool,
        /// Check the configuration only, not the data, weights and benchmark folders it names.
        #[arg(long)]
        config_only: bool,
    },
    /// Writes training pairs as the trainer draws them: left | right | ground truth, one PNG each.
    Samples {
        /// Experiment file (its first run when the file sweeps).
        file: PathBuf,
        /// Output folder.
        #[arg(short, long, default_value = "out/samples")]
        out: PathBuf,
        /// How many pairs: the batch elements of the first steps, in training order.
        #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u16).range(1..))]
        count: u16,
    },
    /// Scores weights on the validation set of an experiment (`[data.validation]`); prints JSON.
    Validate {
        /// Experiment file (its first run when the file sweeps).
        file: PathBuf,
        /// Weights of the experiment's model (dgstereo `.safetensors`); default: its `train.init`.
        #[arg(long)]
        weights: Option<PathBuf>,
    },
}

fn parse_size(text: &str) -> Result<[usize; 2], String> {
    let (h, w) = text.split_once(['x', 'X']).ok_or_else(|| format!("'{text}': expected HEIGHTxWIDTH, e.g. 64x96"))?;
    let parse = |s: &str| s.trim().parse::<usize>().ok().filter(|v| *v >= 8);
    match (parse(h), parse(w)) {
        (Some(h), Some(w)) => Ok([h, w]),
        _ => Err(format!("'{text}': both sides must be whole numbers of at least 8")),
    }
}

pub fn run(command: ExperimentCommand) -> anyhow::Result<ExitCode> {
    match command {
        ExperimentCommand::Check { files, size, iters, show, config_only } => {
            check(&files, size, iters as usize, show, config_only)
        }
        ExperimentCommand::Samples { file, out, count } => samples(&file, &out, count as usize),
        ExperimentCommand::Validate { file, weights } => validate(&file, weights.as_deref()),
    }
}

fn validate(file: &Path, weights: Option<&Path>) -> anyhow::Result<ExitCode> {
    let run = dgstereo_experiment::load_first(file)?;
    let weights = match weights.map(Path::to_path_buf).or_else(|| run.config.train.init.clone()) {
        Some(w) => w,
        None => anyhow::bail!("{}: no --weights given and the experiment has no train.init", file.display()),
    };
    let parts = crate::fetching::parts(dgstereo_train::TrainParts::from(run.config))?;
    let weights = crate::fetching::stereo(&weights, "weights")?;
    let device = dgstereo_core::default_device();
    let model = dgstereo_study::scoring::FinishedRun::with_weights(&parts, &weights, &device)
        .with_context(|| format!("{}: loading {}", file.display(), weights.display()))?;
    let m = dgstereo_study::scoring::evaluate_finished_run(&parts, &model, &device)
        .with_context(|| format!("{}: validation", file.display()))?;
    let report = serde_json::json!({
        "experiment": parts.name, "weights": weights.display().to_string(),
        "validation": serde_json::to_value(&parts.data.validation)?,
        "epe": m.epe, "bad-1": m.bad_1, "bad-2": m.bad_2, "bad-3": m.bad_3, "valid_pixels": m.valid_pixels,
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(ExitCode::SUCCESS)
}

fn samples(file: &Path, out: &Path, count: usize) -> anyhow::Result<ExitCode> {
    let run = dgstereo_experiment::load_first(file)?;
    let (data_config, train) = (&run.config.data, &run.config.train);
    let data = dgstereo_train::batch::TrainingData::new(data_config, train)
        .with_context(|| format!("{}: training data", file.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let batch = train.batch_size.max(1);
    for k in 0..count {
        let (step, element) = (k / batch, k % batch);
        let pair = data.pair(step, element).with_context(|| format!("{}: pair {k}", file.display()))?;
        let truth = colorize(&pair.disparity, display_range(&pair.disparity), true);
        let picture = side_by_side(&[&pair.left, &pair.right, &truth]);
        let path = out.join(format!("sample-{k:03}.png"));
        dgstereo_data::image::save_rgb(&path, &picture)?;
        println!("{}  step {step}, element {element}: {}", path.display(), pair.name);
    }
    Ok(ExitCode::SUCCESS)
}

fn check(files: &[PathBuf], size: [usize; 2], iters: usize, show: bool, config_only: bool) -> anyhow::Result<ExitCode> {
    let device = dgstereo_core::default_device();
    let mut failures = 0usize;
    let mut all_runs = Vec::new();
    for file in files {
        let runs = match dgstereo_experiment::load(file) {
            Ok(runs) => runs,
            Err(e) => {
                failures += 1;
                println!("{:<44} {:>22}  error: {e}", file.display(), "-");
                continue;
            }
        };
        for run in runs {
            let parts = dgstereo_train::TrainParts::from(run.config.clone());
            let on_disk = if config_only {
                Ok(())
            } else {
                crate::fetching::parts(parts)
                    .and_then(|parts| dgstereo_train::preflight::preflight(&parts, &run.config.benchmarks))
                    .map(drop)
            };
            let checked = on_disk.and_then(|()| dgstereo_experiment::smoke_test(&run.config, size, iters, &device));
            match checked {
                Ok(report) => println!("{:<44} {:>22}  OK", run.name, report.parameters_text()),
                Err(e) => {
                    failures += 1;
                    println!("{:<44} {:>22}  error: {}: {e}", run.name, "-", run.source.display());
                }
            }
            if show {
                println!("{}", run.config.to_toml());
            }
            all_runs.push(run);
        }
    }
    if let Err(e) = dgstereo_study::check_distinct_folders(&all_runs) {
        failures += 1;
        println!("error: {e}");
    }
    if failures > 0 {
        eprintln!("{failures} failed");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("64x96"), Ok([64, 96]));
        assert!(parse_size("64").is_err());
        assert!(parse_size("4x96").is_err());
    }
}
