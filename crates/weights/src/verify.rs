//! The checks a downloaded checkpoint passes before it is kept: its SHA-256 (pinned, or the
//! hub's own) and its structure (the checkpoint loads and its tensors show the architecture the
//! catalog names).

use std::io::Read;
use std::path::Path;

use dgstereo_core::{Error, Result, default_device};
use dgstereo_model::checkpoint_config;
use dgstereo_prior::depth_anything::checkpoint::detect_encoder;
use sha2::{Digest, Sha256};

use crate::catalog::{Architecture, NamedWeights};

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

/// Whether `text` is a SHA-256 in hex (the hub's etag of a large file is one).
pub fn is_sha256(text: &str) -> bool {
    text.len() == 64 && text.bytes().all(|b| b.is_ascii_hexdigit())
}

/// Checks that `path` has the SHA-256 `expected`; the error names the file, both sums and `what`.
pub fn check_sha256(path: &Path, expected: &str, what: &str) -> Result<()> {
    let actual = sha256_file(path)?;
    if actual.eq_ignore_ascii_case(expected) {
        Ok(())
    } else {
        Err(Error::format(path, format!("SHA-256 {actual} differs from {what} {expected}: the download is corrupt")))
    }
}

/// Checks that the checkpoint at `path` loads and shows the architecture of `w`.
pub fn check_structure(path: &Path, w: &NamedWeights) -> Result<()> {
    match w.architecture {
        Architecture::RaftStereo(preset) => {
            let detected = checkpoint_config::detect(path, &default_device())
                .map_err(|e| Error::format(path, format!("not a RAFT-Stereo checkpoint: {e}")))?;
            if detected.preset != preset {
                return Err(Error::format(
                    path,
                    format!(
                        "its tensors show {} (preset: {}), not the {} architecture of {}",
                        checkpoint_config::summary(&detected.model),
                        detected.preset.name(),
                        preset.name(),
                        w.name
                    ),
                ));
            }
        }
        Architecture::DepthAnythingV2(encoder) => {
            let detected = detect_encoder(path)
                .map_err(|e| Error::format(path, format!("not a Depth Anything V2 checkpoint: {e}")))?;
            if detected != encoder {
                return Err(Error::format(
                    path,
                    format!("its tensors show the {detected} encoder, not the {encoder} of {}", w.name),
                ));
            }
        }
    }
    Ok(())
}
