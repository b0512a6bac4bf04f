//! The checks a checkpoint passes before it is kept and each time a name is loaded: its SHA-256
//! (the published one where the catalog pins it, else the one a server states, else the one
//! recorded at its first fetch) and its structure (the checkpoint loads and its tensors show the
//! architecture the catalog names).

use std::io::Read;
use std::path::Path;

use dgstereo_core::{Error, Result, default_device};
use dgstereo_model::checkpoint_config;
use dgstereo_prior::depth_anything::checkpoint::detect_encoder;
use sha2::{Digest, Sha256};

use crate::cache::{Cache, stamp};
use crate::catalog::{Architecture, NamedWeights};
use crate::structure::{check_igev, defom_encoder, state_dict_keys};

/// How a fetched file was checked, beside its structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verified {
    /// Its SHA-256 is the one the catalog pins (the publisher's).
    PinnedSha256,
    /// Its SHA-256 is the one the server stated (a strong hub etag); nothing is published.
    ServerSha256,
    /// No SHA-256 was published or stated: structure only; the SHA-256 of this first fetch is
    /// recorded, and later loads must match it.
    StructureOnly,
}

impl Verified {
    /// The check, for people.
    pub fn describe(self) -> &'static str {
        match self {
            Self::PinnedSha256 => "SHA-256 as published",
            Self::ServerSha256 => "SHA-256 as the server stated it",
            Self::StructureOnly => "structure only (no published SHA-256; this fetch's SHA-256 is recorded)",
        }
    }
}

/// The SHA-256 of a file, as lower-case hex.
pub fn sha256_file(path: &Path) -> Result<String> {
    let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut hasher = Sha256::new();
    let mut buffer = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut buffer).map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buffer[..n]);
    }
    Ok(hasher.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

pub use crate::catalog::is_sha256;

/// The SHA-256 an `ETag` header states, if it states one: a strong tag (no `W/`) whose value
/// is 64 hex digits. A weak tag promises equivalent content, not these bytes, and other tags
/// (a git blob id, a date) are no SHA-256: neither is used.
pub fn etag_sha256(etag: &str) -> Option<String> {
    let etag = etag.trim();
    if etag.starts_with("W/") || etag.starts_with("w/") {
        return None;
    }
    let value = etag.trim_matches('"');
    is_sha256(value).then(|| value.to_ascii_lowercase())
}

/// Checks that `actual` (the SHA-256 of `path`) is `expected`; the error names the file, both
/// sums and `what` the expected one is.
pub fn check_sha256(path: &Path, actual: &str, expected: &str, what: &str) -> Result<()> {
    if actual.eq_ignore_ascii_case(expected) {
        Ok(())
    } else {
        Err(Error::format(path, format!("SHA-256 {actual} differs from {what} {expected}")))
    }
}

/// Checks the SHA-256 of a freshly downloaded `path` for `w`: against the catalog's pinned one,
/// else against `stated` (what the server stated), else none; returns the file's SHA-256 and
/// how it was checked. The structure is checked apart ([`check_structure`]).
pub fn check_download(path: &Path, w: &NamedWeights, stated: Option<&str>) -> Result<(String, Verified)> {
    let actual = sha256_file(path)?;
    let verified = match (w.sha256, stated) {
        (Some(pinned), _) => {
            check_sha256(path, &actual, pinned, "the published SHA-256")?;
            Verified::PinnedSha256
        }
        (None, Some(stated)) => {
            check_sha256(path, &actual, stated, "the SHA-256 the server stated")?;
            Verified::ServerSha256
        }
        (None, None) => Verified::StructureOnly,
    };
    Ok((actual, verified))
}

/// How thoroughly [`check_cached`] checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Thoroughness {
    /// Every byte is hashed.
    Hash,
    /// A file whose size and modification time are those recorded with its SHA-256 is taken as
    /// unchanged; any other is hashed (a load: hashing a 1.3 GB ViT-L file each time costs
    /// seconds).
    Stamp,
}

/// Checks a cached file of `w` before it is used: its SHA-256 against the pinned one, else
/// against the one recorded when it was fetched; a file with neither (placed by hand, or
/// fetched by Python's `huggingface_hub`) has its structure checked. What was checked is
/// recorded. The error names the file and both sums.
pub fn check_cached(cache: &Cache, w: &NamedWeights, path: &Path, thoroughness: Thoroughness) -> Result<()> {
    let record = cache.recorded(w)?;
    if let Some(record) = &record
        && thoroughness == Thoroughness::Stamp
        && w.sha256.is_none_or(|pinned| pinned.eq_ignore_ascii_case(&record.sha256))
        && record.stamp.is_some()
        && record.stamp == stamp(path)
    {
        return Ok(());
    }
    let actual = sha256_file(path)?;
    let changed = |e: Error| {
        e.context(format!("{} changed since it was fetched (delete it and fetch {} again)", path.display(), w.name))
    };
    match (w.sha256, &record) {
        (Some(pinned), _) => check_sha256(path, &actual, pinned, "the published SHA-256").map_err(changed)?,
        (None, Some(record)) => check_sha256(
            path,
            &actual,
            &record.sha256,
            &format!("the SHA-256 recorded when it was fetched ({})", cache.record_path(w).display()),
        )
        .map_err(changed)?,
        (None, None) => check_structure(path, w)?,
    }
    if record.is_none_or(|r| r.stamp != stamp(path)) {
        cache.record(w, &actual, path)?;
    }
    Ok(())
}

/// Checks that the checkpoint at `path` loads and shows the architecture of `w`.
pub fn check_structure(path: &Path, w: &NamedWeights) -> Result<()> {
    let refused = |message: String| Error::format(path, message);
    match w.architecture {
        Architecture::RaftStereo(preset) => {
            let detected = checkpoint_config::detect(path, &default_device())
                .map_err(|e| Error::format(path, format!("not a RAFT-Stereo checkpoint: {e}")))?;
            if detected.preset != preset {
                return Err(refused(format!(
                    "its tensors show {} (preset: {}), not the {} architecture of {}",
                    checkpoint_config::summary(&detected.model),
                    detected.preset.name(),
                    preset.name(),
                    w.name
                )));
            }
        }
        Architecture::DepthAnythingV2(encoder) => {
            let detected = detect_encoder(path)
                .map_err(|e| Error::format(path, format!("not a Depth Anything V2 checkpoint: {e}")))?;
            if detected != encoder {
                return Err(refused(format!(
                    "its tensors show the {detected} encoder, not the {encoder} of {}",
                    w.name
                )));
            }
        }
        Architecture::DefomStereo(encoder) => {
            let detected = defom_encoder(&state_dict_keys(path)?).map_err(refused)?;
            if detected != encoder {
                return Err(refused(format!(
                    "its tensors show DEFOM-Stereo with the {detected} encoder, not the {encoder} of {}",
                    w.name
                )));
            }
        }
        Architecture::IgevStereo => check_igev(&state_dict_keys(path)?).map_err(refused)?,
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_strong_sha256_etags_state_a_hash() {
        let sha = "ab".repeat(32);
        assert_eq!(etag_sha256(&format!("\"{sha}\"")), Some(sha.clone()));
        assert_eq!(etag_sha256(&sha.to_uppercase()), Some(sha.clone()));
        assert_eq!(etag_sha256(&format!("W/\"{sha}\"")), None);
        assert_eq!(etag_sha256("\"6f1e2d3c4b5a69788796a5b4c3d2e1f0a1b2c3d4\""), None);
        assert_eq!(etag_sha256("\"5f3a-1b2c\""), None);
    }
}
