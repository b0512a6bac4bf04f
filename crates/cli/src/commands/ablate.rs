//! `dgstereo ablate`: trains (or reuses) every run of the given experiment files, evaluates each
//! final model and writes the ablation table (Markdown, CSV, JSON) into `--out`.
//!
//! Each run trains into `--out/<run name>`. A run folder holding a finished run (`summary.json`
//! and `model.safetensors`) is reused as is; one holding checkpoints only is resumed. Every run is
//! scored on its held-out synthetic validation set (`[data.validation]`, column `synthetic`) and
//! on each of its `[[benchmarks]]` (a real data set under its protocol: EPE and the protocol's
//! headline rate); the table's columns are the union over the runs, NaN where a run lacks one.
//! Runs that differ only in `train.seed` form one row (mean ± std over the seeds,
//! [`dgstereo_study::ablation_table`]). Before any run trains, every run's data, initial weights
//! and benchmark folders are checked ([`dgstereo_train::preflight`], every benchmark sample's
//! headers included), and so are the run folders: two runs of one name, or a folder holding
//! checkpoints or a finished run of another configuration, are refused before anything is written
//! (`study.json` included), so a wrong benchmark path costs seconds, not a trained row. Where a row is one of
//! the paper's, the rows' means also fill the paper's four ablation tables (`paper-tables.md`,
//! `paper-table{2,3,4,5}.csv`), matched by run name; columns are matched to benchmarks by data set
//! (kind and split or weather, [`dgstereo_study::paper_match`]), and `--paper` sets the published
//! figures and our distance from them beside ours and lays every row whose network is a model of
//! the paper's Table 1 (RAFT-Stereo, DEFOM-Stereo, the paper's model) out as Table 1
//! (`paper-table1.csv`, [`dgstereo_study::paper_table1`]). A study stopped by a signal continues where it
//! stopped when the same command runs again. The study is the `dgstereo-study` library
//! ([`dgstereo_study::task`] for one run, [`dgstereo_study::collect()`] for the tables,
//! [`dgstereo_study::slurm`] for `--launcher slurm`); this command parses flags, trains with the
//! binary's progress bar and signals, and prints.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, ValueEnum};
use dgstereo_core::DeviceChoice;
use dgstereo_experiment::ResolvedRun;
use dgstereo_study::paper_tables::paper_run_names;
use dgstereo_study::scores::SYNTHETIC;
use dgstereo_study::slurm::{ArrayJob, Submission};
use dgstereo_study::task::{Scoring, Training, check_run, score_into_folder, training};
use dgstereo_study::{Collected, Study, check_distinct_folders, parts_of, run_folder};

use crate::training::{Session, stop_signals, train_one};

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
        let (study, collected) = dgstereo_study::collect_study(&a.out)?;
        return Ok(show_collected(&collected, &study, &a.out));
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
    let stop = stop_signals()?;
    let runs = dgstereo_experiment::load_all(&a.files)?;
    check_distinct_folders(&runs)?;
    // Everything every run reads, and every run's folder, checked before the first one trains
    // (or is submitted) and before anything is written.
    for run in &runs {
        let context = || format!("{}: run '{}'", run.source.display(), run.name);
        let parts = crate::fetching::parts(parts_of(run.config.clone(), a.steps)).with_context(context)?;
        check_run(&parts, &run.config.benchmarks, &run_folder(&a.out, &run.name)).with_context(context)?;
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
        return submit(&runs, &a);
    }
    for run in &runs {
        if stop.requested() {
            eprintln!("{}: stopped before run '{}'; run the same command again to continue", stop.name(), run.name);
            return Ok(ExitCode::from(stop.exit_status()));
        }
        let status = train_and_score(run, &a, &stop)?;
        if status != ExitCode::SUCCESS {
            return Ok(status);
        }
    }
    let collected = dgstereo_study::collect(&runs, &study, &a.out)?;
    Ok(show_collected(&collected, &study, &a.out))
}

/// Trains (or reuses, or resumes) one run into its folder and stores its scores there; a run
/// stopped by a signal returns the signal's status.
fn train_and_score(
    run: &ResolvedRun,
    a: &AblateArgs,
    stop: &dgstereo_signals::StopSignals,
) -> anyhow::Result<ExitCode> {
    let device = a.device.device()?;
    let session = Session {
        device: &device,
        stop,
        progress: !a.quiet,
        continue_with: "run the same command again to continue (ablate resumes its unfinished runs)",
    };
    let name = &run.name;
    let out = run_folder(&a.out, name);
    let benchmarks = &run.config.benchmarks;
    let parts =
        crate::fetching::parts(parts_of(run.config.clone(), a.steps)).with_context(|| format!("run '{name}'"))?;
    match training(&parts, &out, a.rescore).with_context(|| format!("run '{name}'"))? {
        Training::Finished => println!("{name}: finished run found in {}, reusing it", out.display()),
        Training::LeftOut => {
            println!("{name}: not finished in {}, left out (--rescore trains nothing)", out.display());
            return Ok(ExitCode::SUCCESS);
        }
        Training::Train { resume } => {
            if train_one(parts.clone(), &out, resume, &session)?.stopped {
                return Ok(ExitCode::from(stop.exit_status()));
            }
        }
    }
    let show = |label: &str, m: &dgstereo_eval::Metrics| {
        if label == SYNTHETIC {
            println!("{name}: synthetic EPE {:.3} px, bad-1 {:.2} %, bad-3 {:.2} %", m.epe, m.bad_1, m.bad_3);
        } else if let Some(b) = benchmarks.iter().find(|b| b.label() == label) {
            let shown: Vec<String> =
                b.table_metrics().iter().map(|k| format!("{k} {:.3}", m.get(k).unwrap_or(f64::NAN))).collect();
            println!("{name}: {label} ({} iterations) {}", b.iters, shown.join(", "));
        }
    };
    if score_into_folder(&parts, benchmarks, &out, a.rescore, &device, show)? == Scoring::Reused {
        println!("{name}: scores reused (model and benchmarks unchanged)");
    }
    Ok(ExitCode::SUCCESS)
}

/// Submits the study to Slurm ([`dgstereo_study::slurm`]) and says what was submitted; with
/// `--wait`, the collecting job's status once the tables are written.
fn submit(runs: &[ResolvedRun], a: &AblateArgs) -> anyhow::Result<ExitCode> {
    let submission = Submission {
        exe: std::env::current_exe().context("cannot find this dgstereo binary")?,
        files: &a.files,
        out: &a.out,
        steps: a.steps,
        device: match a.device {
            DeviceChoice::Cpu => "cpu",
            DeviceChoice::Gpu => "gpu",
        },
        sbatch: a.sbatch.as_deref(),
        wait: a.wait,
    };
    let announce = |array: &ArrayJob| {
        println!(
            "submitted array job {} ({} tasks, logs in {}/task-<i>.out); the tables follow in {}",
            array.id,
            array.tasks,
            array.dir.display(),
            array.out.display()
        );
    };
    let collecting = dgstereo_study::slurm::submit(runs, &submission, announce)?;
    match &collecting.log {
        None => {
            let out = std::path::absolute(&a.out).unwrap_or_else(|_| a.out.clone());
            println!(
                "collecting job {} runs after the array (dgstereo ablate --collect --out {})",
                collecting.id,
                out.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Some(log) => {
            print!("{log}");
            Ok(if collecting.success { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
    }
}

/// Prints the tables a study's collection wrote; the status is a failure when a run has no
/// current scores.
fn show_collected(collected: &Collected, study: &Study, out: &std::path::Path) -> ExitCode {
    println!("\n{}", collected.table.to_markdown());
    println!("tables written to {}/ablation.{{md,csv,json}}, curves to ablation.png", out.display());
    if collected.fills_paper_tables() {
        for paper_table in collected.comparisons.iter().filter(|t| t.has_runs()) {
            println!("{}", paper_table.to_markdown(study.paper));
        }
        println!("the paper's columns, matched by data set:");
        for m in &collected.matches {
            println!("  {}", m.describe());
        }
        let numbers: Vec<String> = collected.comparisons.iter().map(|t| t.number.to_string()).collect();
        println!(
            "the paper's tables written to {}/paper-tables.md and paper-table{{{}}}.csv",
            out.display(),
            numbers.join(",")
        );
    } else if study.paper {
        let names = paper_run_names();
        println!(
            "--paper: no row of this study is one of the paper's (its rows are the runs named {}, and the runs of \
             Table 1's models: RAFT-Stereo, DEFOM-Stereo, the paper's model), so there is nothing to set beside \
             the published figures",
            names.join(", ")
        );
    }
    if collected.complete() {
        ExitCode::SUCCESS
    } else {
        let missing = collected.table.missing.len();
        eprintln!("{missing} of {} runs have no current scores (see the table)", collected.runs);
        ExitCode::FAILURE
    }
}
