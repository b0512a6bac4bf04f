//! `dgstereo infer`: disparity of the user's stereo pairs.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

/// Options of inference.
#[derive(Args)]
pub struct InferArgs {
    /// Left image(s): files or glob patterns.
    #[arg(short, long)]
    left: Vec<String>,
    /// Right image(s): files or glob patterns.
    #[arg(short, long)]
    right: Vec<String>,
    /// Output folder.
    #[arg(long, default_value = "out/infer")]
    out: PathBuf,
}

pub fn run(_a: InferArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("dgstereo infer is not implemented yet")
}
