//! What a sample's files say in their headers, read without decoding them: the size of a
//! picture, and the size of a disparity file checked for completeness (a PFM or `.npy` as long
//! as its header promises, a PNG whose chunks reach `IEND`).
//!
//! Design decision: a benchmark is scored only after hours of training, so the files it will
//! read are checked before the first step; decoding every picture of a benchmark then would cost
//! as much as reading it twice, while the headers say what goes wrong in practice (views of
//! different sizes, a ground truth of another size, a file cut short by a copy).

use std::path::Path;

use dgstereo_core::{Error, Result};

use crate::disparity_io::DisparityFormat;

/// The `(width, height)` of a picture (PNG, JPEG, BMP, TIFF, ...), from its header.
pub fn image_size(path: impl AsRef<Path>) -> Result<(usize, usize)> {
    let path = path.as_ref();
    let reader = image::ImageReader::open(path).map_err(|e| Error::io(path, e))?;
    let reader = reader.with_guessed_format().map_err(|e| Error::io(path, e))?;
    let (w, h) = reader.into_dimensions().map_err(|e| crate::image::image_error(path, e))?;
    Ok((w as usize, h as usize))
}

/// The `(width, height)` of a disparity file (format by extension, as
/// [`read_disparity`](crate::read_disparity) reads it), from its header, after checking that the
/// file holds every sample its header promises.
pub fn disparity_size(path: impl AsRef<Path>) -> Result<(usize, usize)> {
    let path = path.as_ref();
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Pfm => crate::pfm::read_pfm_header(path).map(|h| (h.width, h.height)),
        DisparityFormat::KittiPng => crate::kitti_png::read_kitti_png_size(path),
        DisparityFormat::Npy => {
            let header = crate::npy::read_npy_header(path)?;
            crate::npy::disparity_size(&header.shape, path)
        }
    }
}

/// The error for a file of a sample whose size is not its left view's: names both files.
pub fn size_mismatch(path: &Path, what: &str, size: (usize, usize), left: &Path, left_size: (usize, usize)) -> Error {
    Error::format(
        path,
        format!(
            "{what} is {}x{} but the left view {} is {}x{}",
            size.0,
            size.1,
            left.display(),
            left_size.0,
            left_size.1
        ),
    )
}
