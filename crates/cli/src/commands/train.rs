//! `dgstereo train`: trains the run(s) of an experiment file.
//!
//! One run trains into `--out`; a file with a sweep trains each combination into
//! `--out/<run name>` (characters other than letters, digits, `-`, `_`, `.`, `=`, `,` and `+`
//! become `_`; two runs that would share a folder are refused before anything trains). `--steps
//! N` replaces `train.steps` (and so the schedule's length) before the configuration is resolved
//! and stored. `--resume` continues each run from its newest checkpoint, starts a run whose
//! folder holds none, and leaves a finished run as it is (after checking it is the same run), so
//! `train SWEEP.toml --resume` completes a sweep however far it got.
//!
//! Started by `mpirun` or `srun` as several ranks (a build with the `mpi` feature), the ranks
//! train one run together ([`dgstereo_train::train_among`]): the cores of a machine are divided
//! among its ranks, a GPU rank takes its machine's adapter of its local rank, and an error on
//! one rank ends every rank of the job (`MPI_Abort`), since the others would wait for it.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;
use dgstereo_collective::Collective;
use dgstereo_core::DeviceChoice;
use dgstereo_distributed::World;
use dgstereo_train::{RunOptions, TrainParts};

use crate::stop_signals::StopSignals;

/// Options of `dgstereo train`.
#[derive(Args)]
pub struct TrainArgs {
    /// The experiment file.
    pub experiment: PathBuf,
    /// Output folder (log, plot, checkpoints, final model).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Train this many steps instead of the file's `train.steps`.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: Option<u64>,
    /// Continue from the newest checkpoint in the output folder.
    #[arg(long)]
    pub resume: bool,
    /// `cpu` or `gpu`.
    #[arg(long, default_value = "cpu")]
    pub device: DeviceChoice,
    /// No progress bar (log lines still go to log.jsonl).
    #[arg(long)]
    pub quiet: bool,
}

/// A run name as a folder name.
pub fn folder_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.=,+".contains(c) { c } else { '_' }).collect()
}

/// The trainer's parts of a resolved experiment, with `steps` overriding `train.steps`.
pub fn parts_of(mut config: dgstereo_experiment::ExperimentConfig, steps: Option<u64>) -> TrainParts {
    if let Some(s) = steps {
        config.train.steps = s as usize;
    }
    TrainParts::from(config)
}

/// How the runs of one command train: where, whether with a progress bar, what stops them and
/// how the command continues a stopped run.
pub struct Session<'a> {
    /// The device.
    pub device: &'a burn::tensor::Device,
    /// The stop flag and signals.
    pub stop: &'a StopSignals,
    /// Draw a progress bar.
    pub progress: bool,
    /// What the user runs to continue a stopped run (`resume with --resume`).
    pub continue_with: &'static str,
}

/// Checks that no two runs train into one folder: two runs of one name (from two files, or one
/// file given twice), or names that differ only in characters a folder name replaces.
pub fn check_distinct_folders(runs: &[dgstereo_experiment::ResolvedRun]) -> anyhow::Result<()> {
    for (i, run) in runs.iter().enumerate() {
        let folder = folder_name(&run.name);
        let Some(other) = runs[..i].iter().find(|r| folder_name(&r.name) == folder) else { continue };
        let (a, b) = (other.source.display(), run.source.display());
        if other.name == run.name {
            anyhow::bail!(
                "run name '{}' is given twice ({a}, {b}): each run needs a name of its own, since it names the \
                 run's folder and its row; set `name` in one of the files",
                run.name
            );
        }
        anyhow::bail!(
            "runs '{}' ({a}) and '{}' ({b}) would train into one folder, '{folder}': rename one",
            other.name,
            run.name
        );
    }
    Ok(())
}

/// Trains one run into `out`, in this process alone, until done or a signal stops it.
pub fn train_one(
    parts: TrainParts,
    out: &Path,
    resume: bool,
    session: &Session<'_>,
) -> anyhow::Result<dgstereo_train::RunSummary> {
    train_one_among(parts, out, resume, session, &dgstereo_collective::SingleProcess)
}

/// Trains one run into `out` with every rank of `ranks`; rank 0 prints.
fn train_one_among(
    parts: TrainParts,
    out: &Path,
    resume: bool,
    session: &Session<'_>,
    ranks: &dyn Collective,
) -> anyhow::Result<dgstereo_train::RunSummary> {
    let name = parts.name.clone();
    let stop = session.stop;
    // Weights names become files (fetched on first use) before the trainer sees them.
    let parts = crate::fetching::parts(parts).with_context(|| format!("run '{name}'"))?;
    let options = RunOptions {
        out: out.to_path_buf(),
        resume,
        stop_after: None,
        progress: Some(crate::train_progress::observer(session.progress, stop.position())),
        notice: |n| eprintln!("{n}"),
        stop: Some(stop.flag()),
    };
    let summary =
        dgstereo_train::train_among(parts, session.device, &options, ranks).with_context(|| format!("run '{name}'"))?;
    if ranks.rank() != 0 {
        return Ok(summary);
    }
    if summary.untouched {
        println!("{name}: finished run in {}, left as it is ({} steps)", out.display(), summary.steps);
        return Ok(summary);
    }
    if summary.stopped {
        let at = summary.checkpoint.as_ref().map_or(String::new(), |p| format!(" ({})", p.display()));
        eprintln!(
            "{name}: {}: stopped at step {}, checkpoint written{at}; {}",
            stop.name(),
            summary.steps,
            session.continue_with
        );
        return Ok(summary);
    }
    if let Some(r) = summary.last {
        println!(
            "{name}: {} steps, loss {:.4}, train EPE {:.3} px, bad-3 {:.2} %",
            summary.steps, r.loss, r.epe, r.bad3
        );
    }
    if let Some(m) = summary.validation {
        println!("{name}: validation EPE {:.3} px, bad-3 {:.2} %", m.epe, m.bad_3);
    }
    println!("{name}: outputs in {}", out.display());
    Ok(summary)
}

pub fn run(a: TrainArgs) -> anyhow::Result<ExitCode> {
    let world = dgstereo_distributed::join()?;
    world.share_cores();
    let result = train_all(&a, &world);
    if let Err(e) = &result
        && world.size() > 1
    {
        // An error every rank returned together (`Error::Rank`, naming the failing rank) is
        // reported by rank 0, and every rank ends normally. An error of this rank alone is
        // reported here, and ends every rank of the job: the others may be waiting for this one.
        let agreed = e.chain().filter_map(|c| c.downcast_ref::<dgstereo_core::Error>()).any(|c| c.is_rank_failure());
        if !agreed {
            let line = crate::engine::error_line(e);
            eprintln!("error: rank {} of {}: {line}", world.rank(), world.size());
            world.abort(1);
        } else if world.rank() != 0 {
            return Ok(ExitCode::FAILURE);
        }
    }
    result
}

fn train_all(a: &TrainArgs, world: &World) -> anyhow::Result<ExitCode> {
    let stop = StopSignals::install()?;
    let runs = dgstereo_experiment::load(&a.experiment)?;
    check_distinct_folders(&runs)?;
    let device = a.device.device_for_local_rank(world.local_rank(), world.local_size())?;
    let session = Session {
        device: &device,
        stop: &stop,
        progress: !a.quiet && world.rank() == 0,
        continue_with: "resume with --resume",
    };
    let several = runs.len() > 1;
    for run in runs {
        if world.size() == 1 && stop.requested() {
            eprintln!("{}: stopped before run '{}'; {}", stop.name(), run.name, session.continue_with);
            return Ok(stop.exit_code());
        }
        let out = if several { a.out.join(folder_name(&run.name)) } else { a.out.clone() };
        let summary = train_one_among(parts_of(run.config, a.steps), &out, a.resume, &session, world)?;
        if summary.stopped {
            return Ok(stop.exit_code());
        }
    }
    Ok(ExitCode::SUCCESS)
}
