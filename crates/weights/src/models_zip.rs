//! RAFT-Stereo's `models.zip` (the official `download_models.sh`): one ranged download gives
//! all five checkpoints; each member of the catalog is kept once its structure is checked, its
//! SHA-256 recorded (none is published), and the archive is deleted after.

use std::path::Path;

use dgstereo_core::atomic_file::commit_file;
use dgstereo_core::{Error, Result};

use crate::cache::Cache;
use crate::catalog::{CATALOG, Source, Sources};
use crate::http::Http;
use crate::options::FetchOptions;
use crate::verify::{check_structure, sha256_file};

/// Downloads `models.zip` (resuming a partial `models.zip.incomplete`), then keeps each
/// checkpoint of the catalog it holds that passes its checks.
pub(crate) fn download(cache: &Cache, sources: &Sources, http: &Http, options: &FetchOptions) -> Result<()> {
    let dir = cache.raft_stereo_dir();
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let partial = dir.join("models.zip.incomplete");
    http.download(&sources.models_zip, &partial, "models.zip", options)?;
    let extracted = extract_checked(cache, &partial, &dir);
    // A complete archive that fails is not resumed: the next fetch downloads it anew.
    let _ = std::fs::remove_file(&partial);
    extracted.map_err(|e| Error::fetch(&sources.models_zip, format!("refused, nothing was kept: {e}")))
}

fn extract_checked(cache: &Cache, archive: &Path, dir: &Path) -> Result<()> {
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
            let sha256 = sha256_file(&part)?;
            commit_file(&part, &target)?;
            cache.record(w, &sha256, &target)
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
