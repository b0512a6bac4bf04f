//! The first bytes of a file and its length: what the readers that check a header without
//! reading the samples need (`read_npy_header`, `read_pfm_header`).

use std::io::Read;
use std::path::Path;

use dgstereo_core::{Error, Result};

/// The first `at_most` bytes of `path` (fewer for a shorter file) and the file's length.
pub fn read_prefix(path: &Path, at_most: usize) -> Result<(Vec<u8>, u64)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let length = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut prefix = Vec::with_capacity(at_most.min(length as usize));
    file.take(at_most as u64).read_to_end(&mut prefix).map_err(|e| Error::io(path, e))?;
    Ok((prefix, length))
}
