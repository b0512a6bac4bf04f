//! Weights by name: `--weights raftstereo-middlebury`, `--prior-weights depth-anything-v2-small`.
//!
//! Design decision: one [`Fetcher`] turns what a user wrote for a weights option into a file,
//! for every front end (the command line's options and `weights fetch`, the Python `Model`): an
//! existing path is used as it is; a name of the [`catalog`] is looked up in the [`cache`] and,
//! unless offline, downloaded, resumably, under a lock and with timeouts, and kept only after
//! its SHA-256 and its tensors are checked ([`verify`]). The fetcher carries its settings
//! ([`FetchOptions`]: offline, timeout, a progress callback); the front ends build it once from
//! the environment ([`Fetcher::from_env`]) and resolve names before they call the libraries,
//! which take files. Hub files live in the Hugging Face cache layout, so Python's downloads are
//! reused.

#![deny(missing_docs)]

pub mod cache;
pub mod catalog;
pub mod fetch;
mod google_drive;
mod http;
mod hub;
mod models_zip;
pub mod options;
pub mod structure;
pub mod verify;

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use dgstereo_prior::PriorConfig;

pub use cache::Cache;
pub use catalog::{Architecture, CATALOG, NamedWeights, Role, Source, Sources, find};
pub use fetch::Fetched;
pub use options::{FetchOptions, Progress, ProgressFn};
pub use verify::{Thoroughness, Verified};

/// Resolves weights options to files: looks names up in a cache and fetches what is missing.
#[derive(Debug, Clone)]
pub struct Fetcher {
    cache: Cache,
    sources: Sources,
    options: FetchOptions,
}

impl Fetcher {
    /// The cache, servers and options the environment chooses ([`Cache::from_env`],
    /// [`Sources::from_env`], [`FetchOptions::from_env`]): what a front end calls once.
    ///
    /// # Errors
    /// [`Error::Config`] naming the variable for a bad `DGSTEREO_HTTP_TIMEOUT`, or when the
    /// platform has no cache folder and `DGSTEREO_CACHE` is unset.
    pub fn from_env() -> Result<Self> {
        Ok(Self::new(Cache::from_env()?, Sources::from_env()).with_options(FetchOptions::from_env()?))
    }

    /// A fetcher of `cache` from `sources` with the default options (online, the default
    /// timeout, no progress reports).
    pub fn new(cache: Cache, sources: Sources) -> Self {
        Self { cache, sources, options: FetchOptions::default() }
    }

    /// This fetcher with `options`.
    pub fn with_options(self, options: FetchOptions) -> Self {
        Self { options, ..self }
    }

    /// This fetcher, offline or not.
    pub fn offline(self, offline: bool) -> Self {
        Self { options: FetchOptions { offline, ..self.options }, ..self }
    }

    /// The cache.
    pub fn cache(&self) -> &Cache {
        &self.cache
    }

    /// The servers.
    pub fn sources(&self) -> &Sources {
        &self.sources
    }

    /// The options.
    pub fn options(&self) -> &FetchOptions {
        &self.options
    }

    /// The file of `w`: from the cache (unchanged since its SHA-256 was checked against the
    /// published or recorded one: [`Thoroughness::Stamp`]), else downloaded (an error when
    /// offline, naming the command that fetches it).
    pub fn get(&self, w: &NamedWeights) -> Result<PathBuf> {
        self.obtain(w, Thoroughness::Stamp).map(|f| f.path)
    }

    /// As [`Fetcher::get`], hashing a cached file whole, and saying how the file was checked
    /// (`dgstereo weights fetch`).
    pub fn fetch(&self, w: &NamedWeights) -> Result<Fetched> {
        self.obtain(w, Thoroughness::Hash)
    }

    fn obtain(&self, w: &NamedWeights, thoroughness: Thoroughness) -> Result<Fetched> {
        if let Some(path) = self.cache.find(w) {
            verify::check_cached(&self.cache, w, &path, thoroughness)?;
            let verified = if w.sha256.is_some() { Verified::PinnedSha256 } else { Verified::StructureOnly };
            return Ok(Fetched { path, verified });
        }
        if self.options.offline && !matches!(w.source, Source::Page { .. }) {
            return Err(Error::fetch(
                w.origin(&self.sources),
                format!(
                    "not downloaded: {} is not in the cache ({}) and offline mode is on (--offline, DGSTEREO_OFFLINE \
                     or HF_HUB_OFFLINE): run `dgstereo weights fetch {}` where the network is reachable",
                    w.name,
                    self.cache.root().display(),
                    w.name
                ),
            ));
        }
        fetch::download(&self.cache, &self.sources, w, &self.options)
    }

    /// What a weights option names, as a file: an existing path as it is, a [`catalog`] name
    /// through [`Fetcher::get`]; `key` (`weights`, `prior`) names the option in errors, and
    /// `role` is what it takes. A name of an architecture no network here loads
    /// ([`Architecture::unloadable_reason`]) is refused before anything is fetched.
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
        // Refused before any download: a file no network here loads is no use to the option.
        if let Some(reason) = w.architecture.unloadable_reason() {
            return Err(Error::config(key, format!("{} cannot be used here: {reason}", w.name)));
        }
        self.get(w)
    }

    /// The file a stereo weights option (`key`: `weights`, `train.init`) names.
    pub fn resolve_stereo(&self, spec: &Path, key: &str) -> Result<PathBuf> {
        self.resolve(spec, Role::Stereo, key)
    }

    /// `config` with the Depth Anything V2 weights it names resolved (`depth-anything-v2-small`),
    /// inside a cache provider too; `key` names the option in errors.
    pub fn resolve_prior(&self, config: PriorConfig, key: &str) -> Result<PriorConfig> {
        Ok(match config {
            PriorConfig::DepthAnythingV2 { weights, encoder, input_size } if !weights.exists() => {
                let weights = self.resolve(&weights, Role::Prior, key)?;
                PriorConfig::DepthAnythingV2 { weights, encoder, input_size }
            }
            PriorConfig::Cache { dir, inner } => {
                PriorConfig::Cache { dir, inner: Box::new(self.resolve_prior(*inner, key)?) }
            }
            other => other,
        })
    }
}

/// The catalog entry `spec` names when it is a name left unresolved (no file of that name
/// exists): what a library that takes files refuses, saying how to resolve it.
pub fn unresolved(spec: &Path) -> Option<&'static NamedWeights> {
    if spec.exists() { None } else { spec.to_str().filter(|s| is_name(s)).and_then(find) }
}

/// The catalog entry a weights option is: a name, or a file kept under an entry's file name
/// (`raftstereo-sceneflow.pth`, `defomstereo_vits_sceneflow.pth`, as the cache and the
/// publishers' scripts name them).
pub fn named_by(spec: &Path) -> Option<&'static NamedWeights> {
    if let Some(w) = spec.to_str().filter(|s| is_name(s)).and_then(find) {
        return Some(w);
    }
    let file = spec.file_name()?.to_str()?;
    CATALOG.iter().find(|w| w.file_name() == file)
}

/// Checks that a weights option holds no unresolved name ([`unresolved`]); `key` names it.
pub fn check_resolved(spec: &Path, key: &str) -> Result<()> {
    match unresolved(spec) {
        Some(w) => Err(Error::config(
            key,
            format!(
                "'{}' names an official checkpoint: resolve it to its file first (dgstereo_weights::Fetcher::resolve)",
                w.name
            ),
        )),
        None => Ok(()),
    }
}

/// Checks that `config` names no unresolved Depth Anything V2 weights ([`check_resolved`]).
pub fn check_resolved_prior(config: &PriorConfig, key: &str) -> Result<()> {
    match config {
        PriorConfig::DepthAnythingV2 { weights, .. } => check_resolved(weights, key),
        PriorConfig::Cache { inner, .. } => check_resolved_prior(inner, key),
        _ => Ok(()),
    }
}

/// Whether `text` is a weights name rather than a path (experiment files keep names as written).
pub fn is_name(text: &str) -> bool {
    !text.contains(['/', '\\']) && find(text).is_some()
}

/// The names that `role` takes, comma-separated.
pub fn names(role: Role) -> String {
    CATALOG.iter().filter(|w| w.role == role).map(|w| w.name).collect::<Vec<_>>().join(", ")
}
