//! One run of a study, the unit a local study loops over and a Slurm array task runs: checked
//! before anything trains, then trained (by the caller, who shows its progress), then scored
//! into its folder.

use std::path::Path;

use burn::tensor::Device;
use dgstereo_core::Result;
use dgstereo_eval::{BenchmarkConfig, Metrics};
use dgstereo_train::TrainParts;
use dgstereo_train::preflight::preflight;
use dgstereo_train::run::is_finished;
use dgstereo_train::run_identity::check_folder;

use crate::runs::has_checkpoints;
use crate::scores::{cached_scores, save_scores, score};

/// What a run's folder asks of the study before its scores.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Training {
    /// The folder holds this run, finished: it is reused as it is.
    Finished,
    /// Train it, resuming from the folder's checkpoints where `resume`.
    Train {
        /// Whether the folder holds checkpoints of this run to resume from.
        resume: bool,
    },
    /// Not finished, and the study trains nothing (rescoring): the run is left out.
    LeftOut,
}

/// Whether the scores of a run were computed now or reused from its folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scoring {
    /// Computed and stored.
    Scored,
    /// The folder's stored scores are current (model and benchmarks unchanged).
    Reused,
}

/// Checks everything run `parts` reads (data, initial weights, every benchmark sample's headers:
/// [`preflight`]) and its folder `folder`: a folder holding training (checkpoints, a finished run)
/// of another configuration is refused; one whose run never reached a checkpoint is started
/// again. Run on every run of a study before the first one trains, it writes nothing.
///
/// # Errors
/// What [`preflight`] finds, or the folder holds another run.
pub fn check_run(parts: &TrainParts, benchmarks: &[BenchmarkConfig], folder: &Path) -> Result<()> {
    preflight(parts, benchmarks)?;
    if is_finished(folder) || has_checkpoints(folder)? {
        check_folder(folder, &parts.resolved_toml)?;
    }
    Ok(())
}

/// What run `parts` needs in its folder `folder`: reuse a finished run (after checking it is this
/// run), train it (resuming from its checkpoints), or, with `rescore`, leave an unfinished run
/// out.
///
/// # Errors
/// The folder holds a finished run of another configuration, or its checkpoints cannot be
/// listed.
pub fn training(parts: &TrainParts, folder: &Path, rescore: bool) -> Result<Training> {
    if is_finished(folder) {
        check_folder(folder, &parts.resolved_toml)?;
        return Ok(Training::Finished);
    }
    if rescore {
        return Ok(Training::LeftOut);
    }
    Ok(Training::Train { resume: has_checkpoints(folder)? })
}

/// Scores the finished run in `folder` and stores the scores there, unless the stored ones are
/// current and `rescore` is not asked; `scored` sees each score as it is computed.
///
/// # Errors
/// The final model does not load, a set cannot be scored, or the scores cannot be written.
pub fn score_into_folder(
    parts: &TrainParts,
    benchmarks: &[BenchmarkConfig],
    folder: &Path,
    rescore: bool,
    device: &Device,
    scored: impl FnMut(&str, &Metrics),
) -> Result<Scoring> {
    if !rescore && cached_scores(folder, parts, benchmarks).is_some() {
        return Ok(Scoring::Reused);
    }
    let scores = score(parts, benchmarks, folder, device, scored)?;
    save_scores(folder, parts, benchmarks, &scores)?;
    Ok(Scoring::Scored)
}
