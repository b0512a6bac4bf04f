//! Downloading named weights into the [`Cache`], whatever their source: hub files in the
//! Hugging Face layout (`hub.rs`), `models.zip`'s members (`models_zip.rs`), Google Drive files
//! (`google_drive.rs`). Each download runs under the name's lock, resumes a
//! partial file, and is kept under its final name only after its checks pass
//! ([`crate::verify`]); the SHA-256 of what was kept is recorded for later loads.

use std::path::PathBuf;

use dgstereo_core::atomic_file::commit_file;
use dgstereo_core::{Error, Result};

use crate::cache::Cache;
use crate::catalog::{NamedWeights, Source, Sources};
use crate::http::Http;
use crate::options::FetchOptions;
use crate::verify::{Verified, check_download, check_structure};

/// A file fetched for a name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fetched {
    /// Where it is.
    pub path: PathBuf,
    /// How its bytes were checked (its structure always is).
    pub verified: Verified,
}

/// Downloads the named weights `w` into `cache` from `sources` (the caller has checked that
/// they are not there) and returns where they are and how they were checked.
///
/// # Errors
/// [`Error::Fetch`] naming the address for a failed or refused download (what arrived is kept
/// for the next attempt, a refused file is removed); [`Error::Unsupported`] for a file
/// published only on a page (`w.source` is [`Source::Page`]).
pub fn download(cache: &Cache, sources: &Sources, w: &NamedWeights, options: &FetchOptions) -> Result<Fetched> {
    let _lock = cache.lock(match w.source {
        Source::ModelsZip { .. } => "raft-stereo-models",
        _ => w.name,
    })?;
    // Another process may have fetched it while this one waited for the lock.
    if let Some(path) = cache.find(w) {
        let verified = if w.sha256.is_some() { Verified::PinnedSha256 } else { Verified::StructureOnly };
        return Ok(Fetched { path, verified });
    }
    let http = Http::new(options);
    // Each source gives the file, how it was checked and its SHA-256 where it is to be recorded
    // here (`models.zip` records its members itself).
    let (path, verified, sha256) = match w.source {
        Source::Hub { repo, file } => crate::hub::download(cache, sources, w, (repo, file), &http, options)?,
        Source::ModelsZip { .. } => {
            crate::models_zip::download(cache, sources, &http, options)?;
            let path = cache
                .find(w)
                .ok_or_else(|| Error::fetch(&sources.models_zip, format!("the archive holds no {}", w.file_name())))?;
            (path, Verified::StructureOnly, None)
        }
        Source::GoogleDrive { file, ids } => {
            let target = cache.file_path(w).unwrap_or_default();
            let dir = target.parent().map(PathBuf::from).unwrap_or_default();
            std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            let partial = dir.join(format!("{file}.incomplete"));
            let url = crate::google_drive::download(sources, (file, ids), &partial, &http, options)?;
            let checked = check_download(&partial, w, None)
                .and_then(|(sha, verified)| check_structure(&partial, w).map(|()| (sha, verified)));
            match checked {
                Ok((sha256, verified)) => {
                    commit_file(&partial, &target)?;
                    (target, verified, Some(sha256))
                }
                Err(e) => {
                    let _ = std::fs::remove_file(&partial);
                    return Err(Error::fetch(url, format!("{} refused, nothing was kept: {e}", w.name)));
                }
            }
        }
        Source::Page { url, file } => return Err(by_hand(cache, w, url, file)),
    };
    if let Some(sha256) = sha256 {
        cache.record(w, &sha256, &path)?;
    }
    Ok(Fetched { path, verified })
}

/// Why a file published only on a page is not downloaded, and what to do instead.
fn by_hand(cache: &Cache, w: &NamedWeights, url: &str, file: &str) -> Error {
    let place = cache.file_path(w).unwrap_or_default();
    Error::unsupported(
        format!("downloading {}", w.name),
        format!(
            "its publisher shares it in a Google Drive folder, which no program downloads from: get {file} from {url} \
             and give its path to --weights, or put it at {} to use the name (its tensors are checked on first use)",
            place.display()
        ),
    )
}
