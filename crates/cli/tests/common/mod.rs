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

/// Standard output and error together, for assertion messages and searches.
pub fn text(o: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}
