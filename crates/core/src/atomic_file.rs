//! Replacing a file so that a crash leaves either the old file or the whole new one: the new
//! content is written to a temporary file beside it, which [`commit_file`] puts on disk and
//! renames over the target. Checkpoints, weights and reports all go through it.

use std::path::Path;

use crate::{Error, Result};

/// Makes the fully written temporary file `tmp` the file `path`: `fsync` of `tmp`, the rename,
/// then `fsync` of the folder so the rename itself is on disk. `tmp` must lie in `path`'s
/// folder (a rename does not cross file systems).
pub fn commit_file(tmp: &Path, path: &Path) -> Result<()> {
    std::fs::File::open(tmp).and_then(|f| f.sync_all()).map_err(|e| Error::io(tmp, e))?;
    std::fs::rename(tmp, path).map_err(|e| Error::io(path, e))?;
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The target gets the temporary file's content, the temporary file is gone, and a missing
    /// temporary file is an error naming it.
    #[test]
    fn the_temporary_file_replaces_the_target() {
        let dir = std::env::temp_dir().join(format!("dgstereo-commit-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (tmp, path) = (dir.join(".out.tmp"), dir.join("out"));
        std::fs::write(&path, b"old").unwrap();
        std::fs::write(&tmp, b"new").unwrap();
        commit_file(&tmp, &path).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        assert!(!tmp.exists());
        let err = commit_file(&tmp, &path).unwrap_err().to_string();
        assert!(err.contains(".out.tmp"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
