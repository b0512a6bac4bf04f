//! `dgstereo train`: trains the run(s) of an experiment file.
//!
//! One run trains into `--out`; a file with a sweep trains each combination into
//! `--out/<run name>` ([`dgstereo_study::folder_name`]; two runs that would share a folder are
//! refused before anything trains). `--steps
//! N` replaces `train.steps` (and so the schedule's length) before the configuration is resolved
//! and stored. `--resume` continues each run from its newest checkpoint, starts a run whose
//! folder holds none, and leaves a finished run as it is (after checking it is the same run), so
//! `train SWEEP.toml --resume` completes a sweep however far it got.
//!
//! Started by `mpirun` or `srun` as several ranks (a build with the `mpi` feature), the ranks
//! train one run together ([`dgstereo_train::train_among`]): the cores of a machine are divided
//! among its ranks, a GPU rank takes its machine's adapter of its local rank, and an error on
//! one rank ends every rank of the job (`MPI_Abort`), since the others would wait for it.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use dgstereo_collective::Collective;
use dgstereo_core::DeviceChoice;
use dgstereo_distributed::World;
use dgstereo_study::{check_distinct_folders, folder_name, parts_of};

use crate::training::{Session, stop_signals, train_one_among};

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
    let stop = stop_signals()?;
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
            return Ok(ExitCode::from(stop.exit_status()));
        }
        let out = if several { a.out.join(folder_name(&run.name)) } else { a.out.clone() };
        let summary = train_one_among(parts_of(run.config, a.steps), &out, a.resume, &session, world)?;
        if summary.stopped {
            return Ok(ExitCode::from(stop.exit_status()));
        }
    }
    Ok(ExitCode::SUCCESS)
}
