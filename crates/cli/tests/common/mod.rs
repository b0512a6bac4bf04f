//! Running the `dgstereo` binary from integration tests.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository's `assets/` folder.
pub fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets")
}

/// The bundled Cones pair.
pub fn cones_dir() -> PathBuf {
    assets().join("cones")
}

/// Runs the binary with `args`.
pub fn dgstereo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dgstereo")).args(args).output().expect("the dgstereo binary runs")
}

/// Runs `dgstereo infer` on the bundled Cones pair with `extra` arguments.
pub fn infer_cones(extra: &[&str]) -> Output {
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let mut args = vec!["infer", "-l", left.to_str().unwrap(), "-r", right.to_str().unwrap()];
    args.extend_from_slice(extra);
    dgstereo(&args)
}

/// Standard output and error together, for assertion messages and searches.
pub fn text(o: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// The tiny network of the training tests: 8-channel trunks, 16-channel GRUs on one level.
pub const TINY_MODEL: &str = "[model.encoder]\nfeature_dim = 16\ntrunk_dims = [8, 8, 8]\n[model.updater]\nhidden_dims = [16, 16, 16]\nn_gru_layers = 1\n";

/// A small synthetic training source.
pub const SYNTHETIC_SOURCE: &str = "[[data.sources]]\nkind = \"synthetic\"\nwidth = 96\nheight = 48\n";

/// A one-pair validation set of 64x32, scored with two iterations.
pub const TINY_VALIDATION: &str = "[data.validation]\ncount = 1\nwidth = 64\nheight = 32\niters = 2\n";

/// `[train]` for the tests: `steps` steps of batch `batch` on 32x64 crops, two iterations,
/// logging every step, seeded `seed`, checkpoints every `checkpoint_every` steps, no validation
/// before the end; `extra` lines are added to the table.
pub fn tiny_train(steps: usize, batch: usize, seed: u64, checkpoint_every: usize, extra: &str) -> String {
    format!(
        "[train]\nsteps = {steps}\nbatch_size = {batch}\ncrop = [32, 64]\niters = 2\nseed = {seed}\nlog_every = 1\n\
         checkpoint_every = {checkpoint_every}\nvalidate_every = 0\n{extra}"
    )
}

/// Writes `dir/<file>`: run `name` of [`TINY_MODEL`], `train` and `data`, then `extra`.
pub fn write_experiment(dir: &Path, file: &str, name: &str, train: &str, data: &str, extra: &str) -> PathBuf {
    let path = dir.join(file);
    std::fs::write(&path, format!("name = \"{name}\"\n{TINY_MODEL}{train}{data}{extra}")).unwrap();
    path
}
