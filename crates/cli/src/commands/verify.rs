//! `dgstereo verify`: conformance with the official PyTorch code.
//!
//! Each subcommand loads a checkpoint in the official layout, runs it on the input stored in a
//! reference file, prints one line per compared value with its error, and exits with status 1
//! when any is outside the tolerance. `raft-stereo` and `depth-anything-v2` check inference
//! against reference activations; `defom` checks DEFOM-Stereo against the official code's
//! activations with the seeded weights the file's metadata lists, `igev` IGEV-Stereo likewise;
//! `train-step` checks two training steps against the official training loop.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Subcommand};
use dgstereo_model::verify::verify_raft_stereo;
use dgstereo_model::verify_defom::verify_defom;
use dgstereo_model::verify_igev::verify_igev;
use dgstereo_prior::verify_depth_anything_v2;
use dgstereo_train::TrainParts;
use dgstereo_train::verify_step::verify_train_step;

/// Which model to verify.
#[derive(Subcommand)]
pub enum VerifyCommand {
    /// RAFT-Stereo: a `.pth` checkpoint, in the architecture its tensors show (default,
    /// realtime, ...), against a reference activations file. Prints the configuration, then
    /// every tensor the reference holds (features, context states, each iteration's flows);
    /// ends with `final flow max abs error: X`; fails above 1e-3 on flows, 1e-4 relative on
    /// the rest.
    RaftStereo(VerifyArgs),
    /// DEFOM-Stereo: a seeded golden file (`defom_stereo_*_seeded.activations.safetensors`),
    /// whose weights are rebuilt from its metadata and loaded as an official checkpoint, the
    /// configuration read from their keys and shapes. Prints the configuration, then every
    /// tensor the reference holds (Depth Anything V2's features and depth, the initial disparity,
    /// the encoders, every scale and normal update block's outputs, each iteration's disparity);
    /// ends with `final flow max abs error: X` (the final disparity's); fails above 1e-4 px on
    /// disparities, 1e-4 relative on the rest.
    Defom(SeededArgs),
    /// IGEV-Stereo: a seeded golden file (`igev_stereo_seeded.activations.safetensors`), whose
    /// weights are rebuilt from its metadata and loaded as an official checkpoint, the
    /// configuration read from their keys and shapes. Prints the configuration, then every
    /// tensor the reference holds (both views' feature pyramids and stems, the geometry volume's
    /// stages, the superpixel weights, the context encoder, every update block's outputs, the
    /// initial and each iteration's disparity); ends with `final flow max abs error: X` (the
    /// final disparity's); fails above 1e-4 px on disparities, 1e-4 relative on the rest.
    Igev(SeededArgs),
    /// Depth Anything V2 (vits, vitb or vitl, read from the checkpoint): a `.pth` checkpoint
    /// against a reference activations file. Ends with `depth max abs error: X`; fails above
    /// 1e-3 of each tensor's range.
    DepthAnythingV2(VerifyArgs),
    /// Training: two steps of our trainer (the recipe's loss, clipping, AdamW and one-cycle
    /// schedule, frozen batch norm) from a `.pth` checkpoint on the batch of a
    /// `*.train_step.safetensors` reference, with its iterations, step count and learning rate.
    /// Prints the recipe against the reference's, then every iteration's prediction, both
    /// losses, gradient norms and learning rates, each gradient and each parameter's update;
    /// ends with `train step: loss rel err A, grad rel L2 err B (worst: NAME), update agreement
    /// C %: PASSED` (or `FAILED`).
    TrainStep(TrainStepArgs),
}

/// Files of a training-step verification.
#[derive(Args)]
pub struct TrainStepArgs {
    /// The checkpoint (official `.pth` layout).
    #[arg(long)]
    weights: PathBuf,
    /// The reference steps (safetensors).
    #[arg(long)]
    reference: PathBuf,
    /// The experiment whose recipe is verified (its first run); default: every section's
    /// default, the reference's recipe.
    #[arg(long)]
    experiment: Option<PathBuf>,
}

/// The file of a verification on seeded weights.
#[derive(Args)]
pub struct SeededArgs {
    /// The reference activations with the seeded weights' keys in their metadata (safetensors).
    #[arg(long)]
    reference: PathBuf,
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
        VerifyCommand::Defom(a) => {
            let report = verify_defom(&a.reference, &device)?;
            println!("{report}");
            report.passed()
        }
        VerifyCommand::Igev(a) => {
            let report = verify_igev(&a.reference, &device)?;
            println!("{report}");
            report.passed()
        }
        VerifyCommand::DepthAnythingV2(a) => {
            let report = verify_depth_anything_v2(&a.weights, &a.reference, &device)?;
            println!("{report}");
            report.passed
        }
        VerifyCommand::TrainStep(a) => {
            let recipe = recipe(a.experiment.as_deref())?;
            let report = verify_train_step(&a.weights, &a.reference, &recipe, None, &device)?;
            println!("{report}");
            report.passed()
        }
    };
    Ok(if passed { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

/// The trainer's parts of `experiment`'s first run, or of an experiment that sets nothing.
fn recipe(experiment: Option<&Path>) -> anyhow::Result<TrainParts> {
    let config = match experiment {
        Some(file) => dgstereo_experiment::load_first(file)?.config,
        None => dgstereo_experiment::ExperimentConfig::named("defaults"),
    };
    Ok(TrainParts::from(config))
}
