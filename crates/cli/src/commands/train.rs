//! `dgstereo train`.

use std::process::ExitCode;

use clap::Args;

/// Options of `dgstereo train`.
#[derive(Args)]
pub struct TrainArgs {}

pub fn run(_a: TrainArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("dgstereo train is not implemented yet")
}
