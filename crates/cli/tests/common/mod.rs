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
