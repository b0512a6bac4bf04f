//! `dgstereo experiment`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Subcommand;

/// Experiment-file tools.
#[derive(Subcommand)]
pub enum ExperimentCommand {
    /// Resolves and validates files, builds each model and runs one small forward pass.
    Check {
        /// Experiment files.
        files: Vec<PathBuf>,
    },
}

pub fn run(_c: ExperimentCommand) -> anyhow::Result<ExitCode> {
    anyhow::bail!("dgstereo experiment is not implemented yet")
}
