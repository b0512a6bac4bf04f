//! Locating the shared reference data (`../shared` beside the checkout).
//!
//! Tests and tools look for it where `DGSTEREO_SHARED` points, else in a `shared` folder beside
//! any ancestor of the working directory or of the crate. Tests that need it call
//! [`shared_dir_for_test`]: in CI (`CI=true`) a missing folder fails the test, elsewhere the test
//! prints a notice and skips.

use std::path::{Path, PathBuf};

/// The shared reference data folder, if it can be found.
pub fn shared_dir() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("DGSTEREO_SHARED") {
        let p = PathBuf::from(p);
        return p.is_dir().then_some(p);
    }
    let mut starts: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        starts.push(cwd);
    }
    starts.push(PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    for start in starts {
        let mut dir: Option<&Path> = Some(start.as_path());
        while let Some(d) = dir {
            let candidate = d.join("shared");
            if candidate.join("golden").is_dir() || candidate.join("data").is_dir() {
                return Some(candidate);
            }
            dir = d.parent();
        }
    }
    None
}

/// Whether this process runs under CI (`CI` set to `true` or `1`).
pub fn in_ci() -> bool {
    matches!(std::env::var("CI").as_deref(), Ok("true") | Ok("1") | Ok("TRUE"))
}

/// The shared folder for a test that needs `relative` inside it.
///
/// Returns `None` (after printing a notice) when it is missing outside CI; panics in CI, where a
/// missing reference is a failure, not a skip.
pub fn shared_dir_for_test(test: &str, relative: &str) -> Option<PathBuf> {
    match shared_dir() {
        Some(dir) if dir.join(relative).exists() => Some(dir),
        _ => {
            let msg = format!(
                "{test}: shared reference data '{relative}' not found \
                 (looked in DGSTEREO_SHARED and ../shared)"
            );
            if in_ci() {
                panic!("{msg}; it is required in CI");
            }
            eprintln!("SKIPPED {msg}");
            None
        }
    }
}
