//! `dgstereo verify`: conformance with the official PyTorch code.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use dgstereo_model::verify::verify_raft_stereo;

/// Which model to verify.
#[derive(Subcommand)]
pub enum VerifyCommand {
    /// RAFT-Stereo: a `.pth` checkpoint against a reference activations file.
    RaftStereo(VerifyArgs),
}

/// Files of a verification.
#[derive(Args)]
pub struct VerifyArgs {
    /// The checkpoint (official `.pth` layout).
    #[arg(long)]
    weights: PathBuf,
    /// The reference activations (safetensors).
    #[arg(long)]
    reference: PathBuf,
}

pub fn run(cmd: VerifyCommand) -> anyhow::Result<ExitCode> {
    let device = dgstereo_core::default_device();
    match cmd {
        VerifyCommand::RaftStereo(a) => {
            let report = verify_raft_stereo(&a.weights, &a.reference, &device)?;
            println!("{report}");
            Ok(if report.passed() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
    }
}
