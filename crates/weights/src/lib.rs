//! Weights by name: `--weights raftstereo-middlebury`, `--prior-weights depth-anything-v2-small`.
//!
//! Design decision: one [`Fetcher`] turns what a user wrote for a weights option into a file,
//! for every front end (the command line's options and `weights fetch`, the Python `Model`): an
//! existing path is used as it is; a name of the [`catalog`] is looked up in the [`cache`] and,
//! unless offline (`--offline`, `DGSTEREO_OFFLINE=1`, `HF_HUB_OFFLINE=1`), downloaded, resumably
//! and under a lock, and kept only after its SHA-256 and its tensors are checked ([`verify`]).
//! Hub files live in the Hugging Face cache layout, so Python's downloads are reused.

#![deny(missing_docs)]

pub mod cache;
pub mod catalog;
pub mod fetch;
pub mod verify;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use dgstereo_core::{Error, Result};
use dgstereo_prior::PriorConfig;

pub use cache::Cache;
pub use catalog::{CATALOG, NamedWeights, Role, Sources, find};

/// Offline mode for the whole process, set by a command line's `--offline`.
static OFFLINE: AtomicBool = AtomicBool::new(false);

/// Progress bars (on standard error) for the whole process: off unless a front end that talks
/// to a user turns them on (the library itself prints nothing).
static PROGRESS: AtomicBool = AtomicBool::new(false);

/// Turns offline mode on for the whole process (as `DGSTEREO_OFFLINE=1` does).
pub fn set_offline(offline: bool) {
    OFFLINE.store(offline, Ordering::Relaxed);
}

/// Shows download progress bars on standard error for the whole process (a command line's
/// choice; bars are hidden where standard error is no terminal).
pub fn set_progress(progress: bool) {
    PROGRESS.store(progress, Ordering::Relaxed);
}

fn env_flag(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| matches!(v.trim().to_ascii_lowercase().as_str(), "1" | "true" | "yes" | "on"))
}

/// Resolves weights options to files: looks names up in a cache and fetches what is missing.
#[derive(Debug, Clone)]
pub struct Fetcher {
    cache: Cache,
    sources: Sources,
    offline: bool,
    progress: bool,
}

impl Fetcher {
    /// The cache, servers and offline mode the environment (and [`set_offline`],
    /// [`set_progress`]) choose.
    pub fn from_env() -> Result<Self> {
        let offline = OFFLINE.load(Ordering::Relaxed) || env_flag("DGSTEREO_OFFLINE") || env_flag("HF_HUB_OFFLINE");
        let progress = PROGRESS.load(Ordering::Relaxed);
        Ok(Self { cache: Cache::from_env()?, sources: Sources::from_env(), offline, progress })
    }

    /// A fetcher of `cache` from `sources`, online, without progress bars.
    pub fn new(cache: Cache, sources: Sources) -> Self {
        Self { cache, sources, offline: false, progress: false }
    }

    /// This fetcher, offline or not.
    pub fn offline(self, offline: bool) -> Self {
        Self { offline, ..self }
    }

    /// The cache.
    pub fn cache(&self) -> &Cache {
        &self.cache
    }

    /// The servers.
    pub fn sources(&self) -> &Sources {
        &self.sources
    }

    /// The file of `w`: from the cache, else downloaded (an error when offline, naming the
    /// command that fetches it).
    pub fn get(&self, w: &NamedWeights) -> Result<PathBuf> {
        if let Some(path) = self.cache.find(w) {
            return Ok(path);
        }
        if self.offline {
            return Err(Error::Other(format!(
                "{} is not in the cache ({}) and offline mode is on (--offline, DGSTEREO_OFFLINE or \
                 HF_HUB_OFFLINE): run `dgstereo weights fetch {}` where the network is reachable",
                w.name,
                self.cache.root().display(),
                w.name
            )));
        }
        fetch::download(&self.cache, &self.sources, w, self.progress)
    }

    /// What a weights option names, as a file: an existing path as it is, a [`catalog`] name
    /// through [`Fetcher::get`]; `key` (`weights`, `prior`) names the option in errors, and
    /// `role` is what it takes.
    pub fn resolve(&self, spec: &Path, role: Role, key: &str) -> Result<PathBuf> {
        if spec.exists() {
            return Ok(spec.to_path_buf());
        }
        let Some(w) = spec.to_str().and_then(find) else {
            let looks_like_a_name = spec.extension().is_none() && spec.components().count() == 1;
            if looks_like_a_name {
                return Err(Error::config(
                    key,
                    format!(
                        "'{}' is neither a file nor a known weights name ({}; `dgstereo weights list` describes them)",
                        spec.display(),
                        names(role)
                    ),
                ));
            }
            return Ok(spec.to_path_buf());
        };
        if w.role != role {
            let other = match w.role {
                Role::Stereo => "stereo weights (give them to --weights)",
                Role::Prior => "a Depth Anything V2 prior (give it to --prior-weights)",
            };
            return Err(Error::config(key, format!("{} is {other}", w.name)));
        }
        self.get(w)
    }
}

/// The file a stereo weights option (`key`: `weights`, `train.init`) names: an existing path as
/// it is, a name through [`Fetcher::from_env`] (made only then).
pub fn resolve_stereo(spec: &Path, key: &str) -> Result<PathBuf> {
    if spec.exists() {
        return Ok(spec.to_path_buf());
    }
    Fetcher::from_env()?.resolve(spec, Role::Stereo, key)
}

/// `config` with the Depth Anything V2 weights it names resolved as [`resolve_stereo`] does
/// (`depth-anything-v2-small`), inside a cache too; `key` names the option in errors.
pub fn resolve_prior(config: PriorConfig, key: &str) -> Result<PriorConfig> {
    Ok(match config {
        PriorConfig::DepthAnythingV2 { weights, encoder, input_size } if !weights.exists() => {
            let weights = Fetcher::from_env()?.resolve(&weights, Role::Prior, key)?;
            PriorConfig::DepthAnythingV2 { weights, encoder, input_size }
        }
        PriorConfig::Cache { dir, inner } => PriorConfig::Cache { dir, inner: Box::new(resolve_prior(*inner, key)?) },
        other => other,
    })
}

/// Whether `text` is a weights name rather than a path (experiment files keep names as written).
pub fn is_name(text: &str) -> bool {
    !text.contains(['/', '\\']) && find(text).is_some()
}

/// The names that `role` takes, comma-separated.
pub fn names(role: Role) -> String {
    CATALOG.iter().filter(|w| w.role == role).map(|w| w.name).collect::<Vec<_>>().join(", ")
}
