//! Reading and writing disparity maps by file extension: `.pfm`, `.png` (KITTI 16-bit, /256),
//! `.npy` (`float32`/`float64`).

use std::path::Path;

use dgstereo_core::{Error, Result};

use crate::image::DisparityMap;
use crate::{kitti_png, npy, pfm};

/// A disparity file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DisparityFormat {
    /// PFM, `f32`, inf/NaN allowed.
    Pfm,
    /// 16-bit PNG, `value / 256`, 0 = invalid (KITTI, DrivingStereo).
    KittiPng,
    /// NumPy `.npy`.
    Npy,
}

impl DisparityFormat {
    /// The format named by the file's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("pfm") => Ok(Self::Pfm),
            Some("png") => Ok(Self::KittiPng),
            Some("npy") => Ok(Self::Npy),
            _ => Err(Error::format(path, "unknown disparity format (expected .pfm, .png or .npy)")),
        }
    }
}

/// Reads a disparity map, the format chosen by extension.
pub fn read_disparity(path: impl AsRef<Path>) -> Result<DisparityMap> {
    let path = path.as_ref();
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Pfm => pfm::read_pfm_disparity(path),
        DisparityFormat::KittiPng => kitti_png::read_kitti_png(path),
        DisparityFormat::Npy => npy::read_npy_disparity(path),
    }
}

/// Writes a disparity map, the format chosen by extension (PNG loses precision below 1/256 px
/// and stores non-finite or non-positive values as 0).
pub fn write_disparity(path: impl AsRef<Path>, disp: &DisparityMap) -> Result<()> {
    let path = path.as_ref();
    match DisparityFormat::from_path(path)? {
        DisparityFormat::Pfm => pfm::write_pfm_disparity(path, disp),
        DisparityFormat::KittiPng => kitti_png::write_kitti_png(path, disp),
        DisparityFormat::Npy => npy::write_npy_disparity(path, disp),
    }
}
