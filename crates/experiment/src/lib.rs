//! Experiment files: one TOML file per run of the paper's tables, resolved into the complete
//! configuration of a run (model, prior, loss, training, data).
//!
//! An experiment file is a TOML table with the sections of [`ExperimentConfig`]:
//!
//! ```toml
//! name = "+dgia"                       # default: the file's stem
//! description = "RAFT-Stereo + DGIA"   # optional
//! base = "baseline.toml"               # optional: inherit, then override
//!
//! [model.fusion]                       # dgstereo_model::ModelConfig
//! kind = "deformable"
//! [prior]                              # dgstereo_prior::PriorConfig
//! kind = "simulated"
//! [loss]                               # dgstereo_loss::LossConfig
//! kind = "sequence-l1"
//! [train]                              # TrainingConfig
//! [data]                               # TrainingDataConfig
//!
//! [sweep]                              # optional: one run per combination
//! "loss.tau" = [0.8, 0.9, 1.0]
//! ```
//!
//! [`load`] turns a file into one [`ResolvedRun`] per sweep combination; every run is fully
//! resolved (defaults filled in) and validated, and [`ExperimentConfig::to_toml`] writes it back
//! as a file that loads to the same configuration.
//!
//! # Design
//! - **Inheritance** ([`mod@inherit`]): `base` names another file, relative to the inheriting
//!   file; chains are followed and cycles are errors. Tables merge recursively and the
//!   inheriting file wins key by key, except that a table whose `kind` changes is replaced as a
//!   whole (switching `[loss]` from `edge-aware` to `sequence-l1` must not keep `tau`). Arrays are
//!   values and are replaced. `name`, `description` and `base` belong to the file that writes
//!   them and are not inherited; `[sweep]` is inherited like any table.
//! - **Sweeps** ([`mod@sweep`]): the `[sweep]` table maps dotted keys to lists of values; the
//!   runs are the cartesian product (keys in alphabetical order, the last one varying fastest),
//!   named `name/key=value,key=value`. A sweep key must exist in the resolved configuration
//!   (defaults included).
//! - **Errors name the file and the key.** Every key remembers the file that last set it, so a
//!   bad value in a base file is reported against that file. Unknown keys are errors, including
//!   keys next to a variant that ignores them (`[prior] kind = "none"` with `weights = ...`).
//! - **Validation** ([`ExperimentConfig::validate`]) checks values and combinations. A depth
//!   prior must have a consumer and vice versa: fusion or guidance without a prior is an error
//!   (the model cannot run), and a prior without fusion or guidance is an error too (it would
//!   cost a monocular network per pair for nothing, and is almost always an inheritance slip
//!   such as a baseline inheriting the paper's `[prior]`). Files named in the configuration
//!   (checkpoints, data folders) need not exist: validation is about the configuration, and
//!   existence is checked when the provider or data set is built.
//! - **Paths are relative to the file that writes them** ([`mod@paths`]): prior weights, data and
//!   benchmark roots, photo folders and `train.init` are made absolute against the declaring
//!   file's folder as it is read, so an experiment works from any working directory and a file
//!   inheriting from another folder finds its base's data.
//! - A list (`[[benchmarks]]`, `[[data.sources]]`) is a value: a file that writes it replaces the
//!   inherited list whole.
//! - **The schema sits below what executes it.** The `[train]` and `[data]` tables
//!   ([`mod@training`]) are defined here; the trainer depends on this crate, never the reverse,
//!   so whoever reads an experiment (inference, the Python package) does not build the trainer.
//! - [`smoke`] builds a run's model, counts its parameters and runs a tiny forward pass
//!   (`dgstereo experiment check`).
#![deny(missing_docs)]

pub mod config;
pub mod inherit;
pub mod keys;
pub mod launcher;
pub mod paths;
pub mod smoke;
pub mod sweep;
pub mod training;

use std::path::{Path, PathBuf};

pub use config::ExperimentConfig;
pub use dgstereo_core::Problem;
pub use smoke::{SmokeReport, smoke_test, trainable_parameters};
pub use training::{DataSource, PhotoTextures, SyntheticScenes, TrainingConfig, TrainingDataConfig, ValidationConfig};

/// One run of an experiment file: a sweep combination, or the file itself without a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedRun {
    /// The run's name: the file's name, plus `/key=value,...` for a sweep combination.
    pub name: String,
    /// The experiment file it came from (as given to [`load`]).
    pub source: PathBuf,
    /// The complete, validated configuration (`config.name == name`).
    pub config: ExperimentConfig,
}

/// Resolves an experiment file into its runs: follows `base`, merges, expands `[sweep]`, fills
/// in defaults and validates each run.
///
/// # Errors
/// [`dgstereo_core::Error`] naming the file at fault (the given file or one of its bases) and
/// the key: unreadable or malformed files, a missing base, an inheritance cycle, unknown keys,
/// values of the wrong type, sweep keys that do not exist, invalid values and combinations.
pub fn load(path: &Path) -> dgstereo_core::Result<Vec<ResolvedRun>> {
    let document = inherit::read(path)?;
    let runs = sweep::expand(&document)?;
    let mut resolved = Vec::with_capacity(runs.len());
    for run in runs {
        let config = keys::deserialize(&run.table, &run.provenance, path)?;
        if let Some(problem) = config.problems().into_iter().next() {
            let file = keys::file_of(&run.provenance, &problem.key, path);
            return Err(dgstereo_core::Error::format(file, problem.to_string()));
        }
        resolved.push(ResolvedRun { name: config.name.clone(), source: path.to_path_buf(), config });
    }
    Ok(resolved)
}

/// The first run of an experiment file ([`load`]): its only run, or a sweep's first.
///
/// # Errors
/// As [`load`]; a file that defines no run ([`dgstereo_core::Error::Format`], naming it).
pub fn load_first(path: &Path) -> dgstereo_core::Result<ResolvedRun> {
    load(path)?.into_iter().next().ok_or_else(|| dgstereo_core::Error::format(path, "the file defines no run"))
}

/// [`load`] for each file, in order, all runs concatenated.
///
/// # Errors
/// The first file that fails to load.
pub fn load_all(paths: &[PathBuf]) -> dgstereo_core::Result<Vec<ResolvedRun>> {
    let mut runs = Vec::new();
    for path in paths {
        runs.extend(load(path)?);
    }
    Ok(runs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_run_of_a_file_is_its_only_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("only.toml");
        std::fs::write(&path, "name = \"only\"\n").unwrap();
        let run = load_first(&path).unwrap();
        assert_eq!((run.name.as_str(), run.source.as_path()), ("only", path.as_path()));
        assert_eq!(run.config.train, TrainingConfig::default());
        let missing = dir.path().join("missing.toml");
        assert!(load_first(&missing).unwrap_err().to_string().contains("missing.toml"));
    }
}
