//! `dgstereo metrics`: one prediction against ground truth.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

/// Files to score.
#[derive(Args)]
pub struct MetricsArgs {
    /// Predicted disparity (`.pfm`, KITTI 16-bit `.png`, `.npy`).
    #[arg(long)]
    pred: PathBuf,
    /// Ground-truth disparity (same formats); pixels count where it is finite and > 0.
    #[arg(long)]
    gt: PathBuf,
    /// Optional mask picture: only its non-zero pixels count.
    #[arg(long)]
    mask: Option<PathBuf>,
    /// Ignore ground truth at or above this disparity.
    #[arg(long)]
    max_disp: Option<f32>,
}

pub fn run(a: MetricsArgs) -> anyhow::Result<ExitCode> {
    let json = dgstereo_eval::metrics_json(&a.pred, &a.gt, a.mask.as_deref(), a.max_disp)?;
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(ExitCode::SUCCESS)
}
