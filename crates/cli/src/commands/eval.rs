//! `dgstereo eval`.

use std::process::ExitCode;

use clap::Args;

/// Options of `dgstereo eval`.
#[derive(Args)]
pub struct EvalArgs {}

pub fn run(_a: EvalArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("dgstereo eval is not implemented yet")
}
