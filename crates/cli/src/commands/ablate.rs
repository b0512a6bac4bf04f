//! `dgstereo ablate`: trains (or reuses) every run of the given experiment files, evaluates each
//! final model and writes the ablation table (Markdown, CSV, JSON) into `--out`.
//!
//! Each run trains into `--out/<run name>`. A run folder holding a finished run (`summary.json`
//! and `model.safetensors`) is reused as is; one holding checkpoints only is resumed. Every run is
//! scored on its held-out synthetic validation set (`[data.validation]`, column `synthetic`) and
//! on each of its `[[benchmarks]]` (a real data set under its protocol: EPE and the protocol's
//! headline rate); the table's columns are the union over the runs, NaN where a run lacks one.
//! Runs that differ only in `train.seed` form one row (mean ± std over the seeds,
//! [`dgstereo_train::ablation_table`]). Before any run trains, every run's data, initial weights
//! and benchmark folders are checked ([`dgstereo_train::preflight`], every benchmark sample's
//! headers included), and so are the run folders: two runs of one name, or a folder holding
//! checkpoints or a finished run of another configuration, are refused before anything is written
//! (`study.json` included), so a wrong benchmark path costs seconds, not a trained row. Where a row is one of
//! the paper's, the rows' means also fill the paper's four ablation tables (`paper-tables.md`,
//! `paper-table{2,3,4,5}.csv`): rows are matched by run name and columns to benchmarks by data set
//! (kind and split or weather, [`dgstereo_train::paper_match`]), and `--paper` sets the published
//! figures and our distance from them beside ours. A study stopped by a signal continues where it
//! stopped when the same command runs again.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, ValueEnum};
use dgstereo_core::DeviceChoice;
use dgstereo_experiment::ResolvedRun;
use dgstereo_train::preflight::preflight;
use dgstereo_train::run::{checkpoint_dir, is_finished};

use super::ablate_collect::{Study, collect, collect_study};
use super::ablate_scores::{cached_scores, save_scores, score};
use super::train::{Session, check_distinct_folders, folder_name, parts_of, train_one};
use crate::stop_signals::StopSignals;

/// Where the runs of a study train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Launcher {
    /// One after another in this process.
    Local,
    /// One Slurm array job, a task per run, and a job that collects the tables.
    Slurm,
}

/// Options of `dgstereo ablate`.
#[derive(Args)]
pub struct AblateArgs {
    /// Experiment files; every run of each is a row, in order.
    #[arg(required_unless_present = "collect")]
    pub files: Vec<PathBuf>,
    /// Output folder: one sub-folder per run, and the tables.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Train this many steps instead of each file's `train.steps`.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: Option<u64>,
    /// `cpu` or `gpu`.
    #[arg(long, default_value = "cpu")]
    pub device: DeviceChoice,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Show the paper's published figures beside ours in its tables: ours, the paper's, and ours
    /// minus the paper's.
    #[arg(long)]
    pub paper: bool,
    /// Train nothing: score the finished runs again (their scores are otherwise reused while
    /// neither the model nor the benchmarks changed); unfinished runs are left out.
    #[arg(long)]
    pub rescore: bool,
    /// Where the runs train: `local` (one after another here) or `slurm` (a Slurm array job,
    /// then a job collecting the tables).
    #[arg(long, value_enum, default_value = "local")]
    pub launcher: Launcher,
    /// With `--launcher slurm`: return when the tables are written, with the study's status
    /// (refused with the local launcher).
    #[arg(long)]
    pub wait: bool,
    /// With `--launcher slurm`: options for `sbatch` (`"--partition=gpu --gres=gpu:1
    /// --time=72:00:00"`), after those of the files' `[launcher]` tables.
    #[arg(long, allow_hyphen_values = true)]
    pub sbatch: Option<String>,
    /// Write the tables of the study in `--out` from whatever runs have finished (the study's
    /// files are read from its `study.json`).
    #[arg(long)]
    pub collect: bool,
    /// Train and score only run number TASK (0-based) of the study: one Slurm array task.
    #[arg(long, hide = true)]
    pub task: Option<usize>,
}

pub fn run(a: AblateArgs) -> anyhow::Result<ExitCode> {
    if a.collect {
        return collect_study(&a.out);
    }
    if a.launcher != Launcher::Slurm {
        for (given, flag) in [(a.wait, "--wait"), (a.sbatch.is_some(), "--sbatch")] {
            if given {
                anyhow::bail!(
                    "{flag} applies to a study submitted to Slurm (--launcher slurm); a local study runs here and \
                     returns when its tables are written: nothing was run"
                );
            }
        }
    }
    let stop = StopSignals::install()?;
    let runs = dgstereo_experiment::load_all(&a.files)?;
    check_distinct_folders(&runs)?;
    // Everything every run reads, and every run's folder, checked before the first one trains
    // (or is submitted) and before anything is written.
    for run in &runs {
        let context = || format!("{}: run '{}'", run.source.display(), run.name);
        let parts = crate::fetching::parts(parts_of(run.config.clone(), a.steps)).with_context(context)?;
        preflight(&parts, &run.config.benchmarks).with_context(context)?;
        // A folder holding training (checkpoints, a finished run) of another configuration is
        // refused; one whose run never reached a checkpoint is started again.
        let folder = a.out.join(folder_name(&run.name));
        if is_finished(&folder) || has_checkpoints(&folder)? {
            dgstereo_train::run_identity::check_folder(&folder, &parts.resolved_toml).with_context(context)?;
        }
    }
    if let Some(task) = a.task {
        let run = runs.get(task).with_context(|| format!("--task {task}: the study has {} runs", runs.len()))?;
        return train_and_score(run, &a, &stop);
    }
    std::fs::create_dir_all(&a.out).map_err(|e| dgstereo_core::Error::io(&a.out, e))?;
    let files = a.files.iter().map(|f| std::path::absolute(f).unwrap_or_else(|_| f.clone())).collect();
    let study = Study { files, steps: a.steps, paper: a.paper };
    study.write(&a.out)?;
    if a.launcher == Launcher::Slurm {
        let device = match a.device {
            DeviceChoice::Cpu => "cpu",
            DeviceChoice::Gpu => "gpu",
        };
        let submission = super::ablate_slurm::Submission {
            files: &a.files,
            out: &a.out,
            steps: a.steps,
            device,
            sbatch: a.sbatch.as_deref(),
            wait: a.wait,
        };
        return super::ablate_slurm::submit(&runs, &submission);
    }
    for run in &runs {
        if stop.requested() {
            eprintln!("{}: stopped before run '{}'; run the same command again to continue", stop.name(), run.name);
            return Ok(stop.exit_code());
        }
        let status = train_and_score(run, &a, &stop)?;
        if status != ExitCode::SUCCESS {
            return Ok(status);
        }
    }
    collect(&runs, &study, &a.out)
}

/// Trains (or reuses, or resumes) one run into its folder and stores its scores there; a run
/// stopped by a signal returns the signal's status.
fn train_and_score(run: &ResolvedRun, a: &AblateArgs, stop: &StopSignals) -> anyhow::Result<ExitCode> {
    let device = a.device.device()?;
    let session = Session {
        device: &device,
        stop,
        progress: !a.quiet,
        continue_with: "run the same command again to continue (ablate resumes its unfinished runs)",
    };
    let name = &run.name;
    let out = a.out.join(folder_name(name));
    let benchmarks = &run.config.benchmarks;
    let parts =
        crate::fetching::parts(parts_of(run.config.clone(), a.steps)).with_context(|| format!("run '{name}'"))?;
    if is_finished(&out) {
        dgstereo_train::run_identity::check_folder(&out, &parts.resolved_toml)
            .with_context(|| format!("run '{name}'"))?;
        println!("{name}: finished run found in {}, reusing it", out.display());
    } else if a.rescore {
        println!("{name}: not finished in {}, left out (--rescore trains nothing)", out.display());
        return Ok(ExitCode::SUCCESS);
    } else if train_one(parts.clone(), &out, has_checkpoints(&out)?, &session)?.stopped {
        return Ok(stop.exit_code());
    }
    if cached_scores(&out, &parts, benchmarks).is_some() && !a.rescore {
        println!("{name}: scores reused (model and benchmarks unchanged)");
    } else {
        let scores = score(name, &parts, benchmarks, &out, &device)?;
        save_scores(&out, &parts, benchmarks, &scores)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Whether run folder `out` holds checkpoints to resume from.
fn has_checkpoints(out: &Path) -> anyhow::Result<bool> {
    let dir = checkpoint_dir(out);
    Ok(dir.is_dir() && !dgstereo_train::checkpoint::list_checkpoints(&dir)?.is_empty())
}
