//! Downloading named weights into the [`Cache`]: hub files through the hub's client (`hf-hub`,
//! which resumes a partial `.incomplete` blob and places the finished one with a rename),
//! `models.zip` with ranged requests of our own (the archive is no hub file). Nothing is kept
//! under its final name before its checks pass ([`crate::verify`]); a refused download is
//! removed.

use std::fs::OpenOptions;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use dgstereo_core::atomic_file::commit_file;
use dgstereo_core::{Error, Result};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cache::Cache;
use crate::catalog::{CATALOG, NamedWeights, Source, Sources};
use crate::verify::{check_sha256, check_structure, is_sha256};

/// Downloads the named weights `w` into `cache` from `sources` (the caller has checked that
/// they are not there) and returns their path.
pub fn download(cache: &Cache, sources: &Sources, w: &NamedWeights, progress: bool) -> Result<PathBuf> {
    let _lock = cache.lock(match w.source {
        Source::ModelsZip { .. } => "raft-stereo-models",
        Source::Hub { .. } => w.name,
    })?;
    // Another process may have fetched it while this one waited for the lock.
    if let Some(path) = cache.find(w) {
        return Ok(path);
    }
    match w.source {
        Source::Hub { repo, file } => download_from_hub(cache, sources, w, repo, file, progress),
        Source::ModelsZip { .. } => {
            download_models_zip(cache, sources, progress)?;
            cache.find(w).ok_or_else(|| {
                Error::format(
                    cache.raft_stereo_dir().join("models.zip"),
                    format!("the archive holds no {}", w.file_name()),
                )
            })
        }
    }
}

fn download_from_hub(
    cache: &Cache,
    sources: &Sources,
    w: &NamedWeights,
    repo: &str,
    file: &str,
    progress: bool,
) -> Result<PathBuf> {
    let origin = w.origin(sources);
    let api = hf_hub::api::sync::ApiBuilder::from_cache(hf_hub::Cache::new(cache.hub().to_path_buf()))
        .with_endpoint(sources.hub.clone())
        .with_progress(progress)
        .build()
        .map_err(|e| Error::Other(format!("{}: cannot start the hub's client: {e}", w.name)))?;
    let pointer = api
        .model(repo.to_string())
        .download(file)
        .map_err(|e| Error::Other(format!("fetching {} from {origin}: {e}", w.name)))?;
    // The blob is named by the hub's etag, which for a large file is its SHA-256.
    let blob = pointer.canonicalize().map_err(|e| Error::io(&pointer, e))?;
    let etag = blob.file_name().and_then(|n| n.to_str()).unwrap_or_default().to_string();
    let checked = (|| {
        if let Some(pinned) = w.sha256 {
            check_sha256(&blob, pinned, "the pinned SHA-256")?;
        }
        if is_sha256(&etag) {
            check_sha256(&blob, &etag, "the SHA-256 the hub sent")?;
        }
        check_structure(&blob, w)
    })();
    if let Err(e) = checked {
        let _ = std::fs::remove_file(&pointer);
        let _ = std::fs::remove_file(&blob);
        return Err(Error::Other(format!("{} from {origin} refused, nothing was kept: {e}", w.name)));
    }
    Ok(pointer)
}

/// Downloads `models.zip` (resuming a partial `models.zip.incomplete`), then keeps each
/// checkpoint of the catalog it holds that passes its checks; the archive is deleted after.
fn download_models_zip(cache: &Cache, sources: &Sources, progress: bool) -> Result<()> {
    let dir = cache.raft_stereo_dir();
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let partial = dir.join("models.zip.incomplete");
    download_resumable(&sources.models_zip, &partial, progress)?;
    let extracted = extract_checked(&partial, &dir);
    // A complete archive that fails is not resumed: the next fetch downloads it anew.
    let _ = std::fs::remove_file(&partial);
    extracted.map_err(|e| Error::Other(format!("{} refused, nothing was kept: {e}", sources.models_zip)))
}

fn extract_checked(archive: &Path, dir: &Path) -> Result<()> {
    let file = std::fs::File::open(archive).map_err(|e| Error::io(archive, e))?;
    let mut zip = zip::ZipArchive::new(file)
        .map_err(|e| Error::format(archive, format!("not a zip archive ({e}): the download is corrupt")))?;
    let mut kept = 0;
    for index in 0..zip.len() {
        let mut entry = zip.by_index(index).map_err(|e| Error::format(archive, e.to_string()))?;
        let base = entry.name().rsplit('/').next().unwrap_or_default().to_string();
        let Some(w) = CATALOG.iter().find(|w| matches!(w.source, Source::ModelsZip { member } if member == base))
        else {
            continue;
        };
        let target = dir.join(&base);
        let part = dir.join(format!(".{base}.part"));
        let written = (|| {
            let mut out = std::fs::File::create(&part).map_err(|e| Error::io(&part, e))?;
            std::io::copy(&mut entry, &mut out)
                .map_err(|e| Error::format(archive, format!("{base} does not unpack: {e}")))?;
            check_structure(&part, w)?;
            commit_file(&part, &target)
        })();
        if let Err(e) = written {
            let _ = std::fs::remove_file(&part);
            return Err(e);
        }
        kept += 1;
    }
    if kept == 0 {
        return Err(Error::format(archive, "the archive holds none of the official checkpoints"));
    }
    Ok(())
}

/// Downloads `url` into `partial`, continuing from the bytes it already has with a ranged
/// request (a server that ignores the range sends the whole file, which then replaces them).
/// Redirects are followed. On an error the bytes received so far stay for the next attempt.
pub fn download_resumable(url: &str, partial: &Path, progress: bool) -> Result<()> {
    let have = std::fs::metadata(partial).map(|m| m.len()).unwrap_or(0);
    let mut request = ureq::AgentBuilder::new().try_proxy_from_env(true).build().get(url);
    if have > 0 {
        request = request.set("Range", &format!("bytes={have}-"));
    }
    let response = match request.call() {
        Ok(r) => r,
        // The partial file is already whole (or longer than the file now is): start again.
        Err(ureq::Error::Status(416, _)) if have > 0 => {
            std::fs::remove_file(partial).map_err(|e| Error::io(partial, e))?;
            return download_resumable(url, partial, progress);
        }
        Err(e) => return Err(Error::Other(format!("fetching {url}: {e}"))),
    };
    let resumed = response.status() == 206;
    let start = if resumed { have } else { 0 };
    let total = match response.header("Content-Range").and_then(|r| r.rsplit('/').next()) {
        Some(t) if resumed => t.parse::<u64>().ok(),
        _ => response.header("Content-Length").and_then(|l| l.parse::<u64>().ok()),
    };
    let mut out = OpenOptions::new()
        .create(true)
        .write(true)
        .append(resumed)
        .truncate(!resumed)
        .open(partial)
        .map_err(|e| Error::io(partial, e))?;
    let bar = if progress { ProgressBar::new(total.unwrap_or(0)) } else { ProgressBar::hidden() };
    bar.set_style(
        ProgressStyle::with_template("{msg} {wide_bar} {bytes}/{total_bytes} {bytes_per_sec} {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(url.rsplit('/').next().unwrap_or(url).split('?').next().unwrap_or_default().to_string());
    bar.set_position(start);
    let mut reader = response.into_reader();
    let mut buffer = vec![0u8; 1 << 16];
    let mut written = start;
    loop {
        let n = reader.read(&mut buffer).map_err(|e| {
            Error::Other(format!(
                "fetching {url}: the connection broke after {written} bytes ({e}); fetch again to resume"
            ))
        })?;
        if n == 0 {
            break;
        }
        out.write_all(&buffer[..n]).map_err(|e| Error::io(partial, e))?;
        written += n as u64;
        bar.set_position(written);
    }
    out.sync_all().map_err(|e| Error::io(partial, e))?;
    bar.finish_and_clear();
    if let Some(total) = total
        && written != total
    {
        return Err(Error::Other(format!("fetching {url}: got {written} of {total} bytes; fetch again to resume")));
    }
    Ok(())
}
