//! Weights names turned into files before the library crates see them (they take files): one
//! [`Fetcher`] from the environment and `--offline`, whose downloads this binary draws as
//! progress bars on standard error.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use dgstereo_core::Result;
use dgstereo_prior::PriorConfig;
use dgstereo_train::TrainParts;
use dgstereo_weights::{FetchOptions, Fetcher, Progress, ProgressFn};
use indicatif::{ProgressBar, ProgressStyle};

/// `--offline`, set once by `main` before any command runs.
static OFFLINE: OnceLock<bool> = OnceLock::new();

/// Takes `--offline` for every fetcher made after.
pub fn set_offline(offline: bool) {
    let _ = OFFLINE.set(offline);
}

/// The fetcher of the environment ([`Fetcher::from_env`]), offline with `--offline` too, with
/// progress bars.
pub fn fetcher() -> Result<Fetcher> {
    let fetcher = Fetcher::from_env()?;
    let offline = fetcher.options().offline || OFFLINE.get().copied().unwrap_or(false);
    let options = FetchOptions { offline, progress: Some(bars()), ..fetcher.options().clone() };
    Ok(fetcher.with_options(options))
}

/// One bar per file being downloaded (hidden where standard error is no terminal).
fn bars() -> ProgressFn {
    let bars: Mutex<HashMap<String, ProgressBar>> = Mutex::new(HashMap::new());
    Arc::new(move |p: &Progress| {
        let mut bars = bars.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let bar = bars.entry(p.file.clone()).or_insert_with(|| {
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template("{msg} {wide_bar} {bytes}/{total_bytes} {bytes_per_sec} {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_message(p.file.clone());
            bar
        });
        if let Some(total) = p.total {
            bar.set_length(total);
        }
        bar.set_position(p.done);
        if p.finished {
            bar.finish_and_clear();
            bars.remove(&p.file);
        }
    })
}

/// A stereo weights option (`key`: `weights`) as a file: an existing path as it is, a name
/// fetched.
pub fn stereo(spec: &Path, key: &str) -> Result<PathBuf> {
    if spec.exists() { Ok(spec.to_path_buf()) } else { fetcher()?.resolve_stereo(spec, key) }
}

/// `config` with the Depth Anything V2 weights it names as files (`key`: `prior`).
pub fn prior(config: PriorConfig, key: &str) -> Result<PriorConfig> {
    if names_missing_file(&config) { fetcher()?.resolve_prior(config, key) } else { Ok(config) }
}

/// `parts` with `train.init` and the prior's weights as files.
pub fn parts(parts: TrainParts) -> Result<TrainParts> {
    let init_missing = parts.train.init.as_ref().is_some_and(|init| !init.exists());
    if init_missing || names_missing_file(&parts.prior) { parts.with_named_weights(&fetcher()?) } else { Ok(parts) }
}

fn names_missing_file(config: &PriorConfig) -> bool {
    match config {
        PriorConfig::DepthAnythingV2 { weights, .. } => !weights.exists(),
        PriorConfig::Cache { inner, .. } => names_missing_file(inner),
        _ => false,
    }
}
