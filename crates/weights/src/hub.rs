//! Downloading a file of a Hugging Face model repository into the Hugging Face cache layout
//! (`models--owner--name/blobs/SHA256`, `snapshots/COMMIT/FILE` linking to it, `refs/main`), so
//! Python's `huggingface_hub` and this crate share their downloads.
//!
//! Design decision: one GET of `ENDPOINT/REPO/resolve/main/FILE` without following redirects
//! reads what the hub states beside the file (`x-repo-commit`, `x-linked-etag`: the file's
//! SHA-256, `x-linked-size`), then the body comes from where it points, resumed with a range.
//! None of these headers is required: a static mirror (`python3 -m http.server`) that serves the
//! file at that path works, checked against the catalog's pinned SHA-256.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};

use crate::cache::Cache;
use crate::catalog::{NamedWeights, Sources};
use crate::http::{Http, Saved, join};
use crate::options::FetchOptions;
use crate::verify::{Verified, check_download, check_structure, etag_sha256};

/// The snapshot folder of a file fetched from a server that names no commit.
const MIRROR_REVISION: &str = "mirror";

/// What the hub states beside a file.
struct Stated {
    commit: Option<String>,
    sha256: Option<String>,
}

impl Stated {
    fn of(response: &ureq::Response) -> Self {
        let header = |name: &str| response.header(name).map(str::trim).filter(|v| !v.is_empty());
        let commit = header("x-repo-commit")
            .filter(|c| c.len() <= 64 && c.bytes().all(|b| b.is_ascii_alphanumeric()))
            .map(str::to_string);
        // The hub sends the LFS object's id as `x-linked-etag` on its redirect; a server that
        // sends the file itself may send an `ETag` of it.
        let sha256 = header("x-linked-etag").or_else(|| header("etag")).and_then(etag_sha256);
        Self { commit, sha256 }
    }
}

/// Downloads `file` of the model repository `repo` for `w` into `cache`, checks it, and returns
/// the snapshot path, how it was checked and its SHA-256. Nothing is placed before the checks pass; a refused
/// file is removed.
pub(crate) fn download(
    cache: &Cache,
    sources: &Sources,
    w: &NamedWeights,
    (repo, file): (&str, &str),
    http: &Http,
    options: &FetchOptions,
) -> Result<(PathBuf, Verified, Option<String>)> {
    let url = format!("{}/{repo}/resolve/main/{file}", sources.hub);
    let repo_dir = cache.hub().join(format!("models--{}", repo.replace('/', "--")));
    let blobs = repo_dir.join("blobs");
    std::fs::create_dir_all(&blobs).map_err(|e| Error::io(&blobs, e))?;
    let display_name = file.rsplit('/').next().unwrap_or(file);
    // Partial files are named by the hash they must reach, so a resumed download continues the
    // bytes of the same file.
    let stem = w.sha256.map_or_else(|| display_name.replace('.', "_"), str::to_string);
    let partial = blobs.join(format!("{stem}.incomplete"));
    let have = std::fs::metadata(&partial).map(|m| m.len()).unwrap_or(0);
    let first = http.get(&url, have, false)?;
    let stated = Stated::of(&first);
    if (300..400).contains(&first.status()) {
        let location = first
            .header("Location")
            .map(|l| join(&url, l))
            .ok_or_else(|| Error::fetch(&url, format!("a redirect ({}) without a Location", first.status())))?;
        http.download(&location, &partial, display_name, options).map_err(|e| e.context(format!("from {url}")))?;
    } else if http.save(first, &url, &partial, have, display_name, options)? == Saved::Restart {
        http.download(&url, &partial, display_name, options)?;
    }
    let checked = check_download(&partial, w, stated.sha256.as_deref())
        .and_then(|(sha, verified)| check_structure(&partial, w).map(|()| (sha, verified)));
    let (sha256, verified) = match checked {
        Ok(checked) => checked,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            return Err(Error::fetch(&url, format!("{} refused, nothing was kept: {e}", w.name)));
        }
    };
    let blob = blobs.join(&sha256);
    std::fs::rename(&partial, &blob).map_err(|e| Error::io(&blob, e))?;
    let commit = match stated.commit {
        Some(commit) => commit,
        None => read_ref(&repo_dir)?.unwrap_or_else(|| MIRROR_REVISION.to_string()),
    };
    let pointer = place(&repo_dir, &commit, file, &sha256)?;
    Ok((pointer, verified, Some(sha256)))
}

/// The commit `refs/main` names, if it names one.
fn read_ref(repo_dir: &Path) -> Result<Option<String>> {
    let path = repo_dir.join("refs").join("main");
    match std::fs::read_to_string(&path) {
        Ok(text) => Ok(Some(text.trim().to_string()).filter(|c| !c.is_empty())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(&path, e)),
    }
}

/// Points `refs/main` at `commit` and `snapshots/COMMIT/FILE` at the blob `sha256` (a relative
/// link where the platform has them, else a copy); returns the snapshot path.
fn place(repo_dir: &Path, commit: &str, file: &str, sha256: &str) -> Result<PathBuf> {
    let refs = repo_dir.join("refs");
    std::fs::create_dir_all(&refs).map_err(|e| Error::io(&refs, e))?;
    let main = refs.join("main");
    if read_ref(repo_dir)?.as_deref() != Some(commit) {
        std::fs::write(&main, commit).map_err(|e| Error::io(&main, e))?;
    }
    let pointer = repo_dir.join("snapshots").join(commit).join(file);
    let parent = pointer.parent().unwrap_or(repo_dir);
    std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    if pointer.symlink_metadata().is_ok() {
        std::fs::remove_file(&pointer).map_err(|e| Error::io(&pointer, e))?;
    }
    let blob = repo_dir.join("blobs").join(sha256);
    link_or_copy(&blob, &pointer, file.split('/').count() + 1)?;
    Ok(pointer)
}

#[cfg(unix)]
fn link_or_copy(blob: &Path, pointer: &Path, depth: usize) -> Result<()> {
    let name = blob.file_name().and_then(|n| n.to_str()).unwrap_or_default();
    let target = format!("{}blobs/{name}", "../".repeat(depth));
    std::os::unix::fs::symlink(target, pointer).map_err(|e| Error::io(pointer, e))
}

#[cfg(not(unix))]
fn link_or_copy(blob: &Path, pointer: &Path, _depth: usize) -> Result<()> {
    std::fs::copy(blob, pointer).map(drop).map_err(|e| Error::io(pointer, e))
}
