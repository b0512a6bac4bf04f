//! Where named weights are kept: `$DGSTEREO_CACHE`, else the platform's cache folder
//! (`~/.cache/dgstereo` on Linux). Hub files are kept in the Hugging Face cache layout
//! (`models--owner--name/{blobs,snapshots,refs}`): in the Hugging Face cache itself
//! (`$HF_HOME/hub`, else `~/.cache/huggingface/hub`) unless `DGSTEREO_CACHE` is set, and a file
//! Python's `huggingface_hub` already downloaded there is used as it is. Beside the files, the
//! cache records the SHA-256 of each one it fetched or checked, with its size and modification
//! time (`sha256/NAME`), so a later load notices a file that changed.

use std::fs::File;
use std::path::{Path, PathBuf};

use dgstereo_core::atomic_file::commit_file;
use dgstereo_core::{Error, Result};

use crate::catalog::{NamedWeights, Source, is_sha256};

/// The folders named weights are kept in and looked up in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cache {
    /// Our own folder: the files of every source but the hub, the records and the locks.
    root: PathBuf,
    /// The Hugging Face cache new hub files go to.
    hub: PathBuf,
    /// Another Hugging Face cache searched for hub files (Python's, when `hub` is ours).
    shared_hub: Option<PathBuf>,
}

impl Cache {
    /// The cache the environment chooses (see the module's documentation).
    pub fn from_env() -> Result<Self> {
        let python_hub = hf_hub::Cache::from_env().path().clone();
        match std::env::var_os("DGSTEREO_CACHE").filter(|v| !v.is_empty()) {
            Some(root) => Ok(Self::at(PathBuf::from(root)).with_shared_hub(python_hub)),
            None => {
                let base = dirs::cache_dir().ok_or_else(|| {
                    Error::config("DGSTEREO_CACHE", "this platform has no cache folder: set DGSTEREO_CACHE to one")
                })?;
                Ok(Self { root: base.join("dgstereo"), hub: python_hub, shared_hub: None })
            }
        }
    }

    /// A cache wholly inside `root` (hub files in `root/huggingface/hub`).
    pub fn at(root: PathBuf) -> Self {
        let hub = root.join("huggingface").join("hub");
        Self { root, hub, shared_hub: None }
    }

    /// This cache, also looking for hub files in the Hugging Face cache `hub`.
    pub fn with_shared_hub(self, hub: PathBuf) -> Self {
        let shared_hub = (hub != self.hub).then_some(hub);
        Self { shared_hub, ..self }
    }

    /// Our own folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The Hugging Face cache new hub files go to.
    pub fn hub(&self) -> &Path {
        &self.hub
    }

    /// The folder `models.zip`'s checkpoints are kept in.
    pub fn raft_stereo_dir(&self) -> PathBuf {
        self.root.join("raft-stereo")
    }

    /// Where a file of `w` from any source but the hub is kept: `models.zip`'s in
    /// `raft-stereo/`, Google Drive's in `google-drive/`, one downloaded by hand in a folder of
    /// its name (`igev-stereo-sceneflow/sceneflow.pth`). `None` for hub files.
    pub fn file_path(&self, w: &NamedWeights) -> Option<PathBuf> {
        match w.source {
            Source::ModelsZip { member } => Some(self.raft_stereo_dir().join(member)),
            Source::GoogleDrive { file, .. } => Some(self.root.join("google-drive").join(file)),
            Source::Page { file, .. } => Some(self.root.join(w.name).join(file)),
            Source::Hub { .. } => None,
        }
    }

    /// Where `w` is, if it is in the cache.
    pub fn find(&self, w: &NamedWeights) -> Option<PathBuf> {
        match w.source {
            Source::Hub { repo, file } => std::iter::once(&self.hub)
                .chain(self.shared_hub.as_ref())
                .find_map(|hub| hf_hub::Cache::new(hub.clone()).model(repo.to_string()).get(file))
                .filter(|p| p.is_file()),
            _ => self.file_path(w).filter(|p| p.is_file()),
        }
    }

    /// The file that records the SHA-256 of `w` as it was fetched.
    pub fn record_path(&self, w: &NamedWeights) -> PathBuf {
        self.root.join("sha256").join(w.name)
    }

    /// What is recorded for `w`, if anything.
    pub fn recorded(&self, w: &NamedWeights) -> Result<Option<Record>> {
        let path = self.record_path(w);
        let text = match std::fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(Error::io(&path, e)),
        };
        let mut lines = text.lines();
        match lines.next().and_then(|l| l.split_whitespace().next()) {
            Some(sha) if is_sha256(sha) => Ok(Some(Record {
                sha256: sha.to_ascii_lowercase(),
                stamp: lines.next().map(str::trim).filter(|l| !l.is_empty()).map(str::to_string),
            })),
            _ => Err(Error::format(&path, "not a SHA-256 record: delete it, and the file it names, and fetch again")),
        }
    }

    /// Records `sha256` for `w`, whose file is `file`: `sha256sum`'s line, then the file's size
    /// and modification time ([`stamp`]).
    pub fn record(&self, w: &NamedWeights, sha256: &str, file: &Path) -> Result<()> {
        let path = self.record_path(w);
        let dir = self.root.join("sha256");
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let tmp = dir.join(format!(".{}.tmp", w.name));
        let stamp = stamp(file).unwrap_or_default();
        std::fs::write(&tmp, format!("{sha256}  {}\n{stamp}\n", file.display())).map_err(|e| Error::io(&tmp, e))?;
        commit_file(&tmp, &path)
    }

    /// Holds the lock of `key` until the guard is dropped, waiting for another process or
    /// thread that holds it: two fetches of one name download it once.
    pub fn lock(&self, key: &str) -> Result<FetchLock> {
        let dir = self.root.join("locks");
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let path = dir.join(format!("{key}.lock"));
        let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
        file.lock().map_err(|e| Error::io(&path, e))?;
        Ok(FetchLock { _file: file })
    }
}

/// What the cache recorded of a file it fetched or checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    /// Its SHA-256.
    pub sha256: String,
    /// Its size and modification time when that SHA-256 was computed ([`stamp`]).
    pub stamp: Option<String>,
}

/// The size and modification time of `path` (links followed), as a record keeps them: a file
/// whose stamp is unchanged has not been written since.
pub fn stamp(path: &Path) -> Option<String> {
    let meta = std::fs::metadata(path).ok()?;
    let modified = meta.modified().ok()?.duration_since(std::time::UNIX_EPOCH).ok()?;
    Some(format!("{} bytes, modified {}.{:09}", meta.len(), modified.as_secs(), modified.subsec_nanos()))
}

/// An exclusive lock on one fetch, released when dropped (or when the process ends).
#[derive(Debug)]
pub struct FetchLock {
    _file: File,
}
