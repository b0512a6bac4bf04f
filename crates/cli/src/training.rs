//! Training one run from the command line: the trainer's loop with the binary's progress bar,
//! its stop signals ([`dgstereo_signals`], said on standard error) and what it prints when a run
//! ends; `train` and `ablate` both train this way.

use std::path::Path;

use anyhow::Context;
use dgstereo_collective::Collective;
use dgstereo_train::{RunOptions, TrainParts};

use dgstereo_signals::{SignalEvent, StopSignals};

/// Receives SIGINT, SIGTERM and SIGUSR1: the first stops the run after its step, a second one (a
/// second or more later) ends the process at once, saying what that drops.
pub fn stop_signals() -> anyhow::Result<StopSignals> {
    Ok(StopSignals::install(|event| match event {
        SignalEvent::Stopping { signal } => eprintln!(
            "{signal}: stopping after the current step, with a checkpoint \
             (a second signal, a second or more from now, stops at once)"
        ),
        SignalEvent::StopNow { signal, dropped, status } => {
            eprintln!("{signal} again: stopped at once; {dropped}");
            std::process::exit(*status);
        }
    })?)
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
pub fn train_one_among(
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
