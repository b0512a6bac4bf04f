//! `dgstereo verify`: conformance with the official PyTorch code.
//!
//! Each subcommand loads a checkpoint in the official layout, runs it on the input stored in a
//! reference activations file, prints one line per reference tensor with its largest absolute
//! error, and exits with status 1 when any tensor is outside the tolerance.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use dgstereo_model::verify::verify_raft_stereo;
use dgstereo_prior::verify_depth_anything_v2;

/// Which model to verify.
#[derive(Subcommand)]
pub enum VerifyCommand {
    /// RAFT-Stereo: a `.pth` checkpoint against a reference activations file.
    RaftStereo(VerifyArgs),
    /// Depth Anything V2 (vits, vitb or vitl, read from the checkpoint): a `.pth` checkpoint
    /// against a reference activations file. Ends with `depth max abs error: X`; fails above
    /// 1e-3 of each tensor's range.
    DepthAnythingV2(VerifyArgs),
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
    let passed = match cmd {
        VerifyCommand::RaftStereo(a) => {
            let report = verify_raft_stereo(&a.weights, &a.reference, &device)?;
            println!("{report}");
            report.passed()
        }
        VerifyCommand::DepthAnythingV2(a) => {
            let report = verify_depth_anything_v2(&a.weights, &a.reference, &device)?;
            println!("{report}");
            report.passed
        }
    };
    Ok(if passed { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
