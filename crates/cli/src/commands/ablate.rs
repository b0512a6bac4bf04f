//! `dgstereo ablate`.

use std::process::ExitCode;

use clap::Args;

/// Options of `dgstereo ablate`.
#[derive(Args)]
pub struct AblateArgs {}

pub fn run(_a: AblateArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("dgstereo ablate is not implemented yet")
}
