//! NumPy `.npy` disparity maps, on the workspace's one `.npy` codec ([`dgstereo_formats::npy`],
//! re-exported here).

use std::path::Path;

use dgstereo_core::{Error, Result};
pub use dgstereo_formats::npy::*;

use crate::image::DisparityMap;

/// Reads a `.npy` disparity: shape `(H, W)`, or 3-D with one dimension of size 1
/// (`(1, H, W)` or `(H, W, 1)`).
pub fn read_npy_disparity(path: impl AsRef<Path>) -> Result<DisparityMap> {
    let path = path.as_ref();
    let arr = read_npy(path)?;
    let (w, h) = disparity_size(&arr.shape, path)?;
    Ok(DisparityMap { width: w, height: h, data: arr.data })
}

/// The `(width, height)` of a `.npy` disparity of `shape`: `(H, W)`, `(1, H, W)` or `(H, W, 1)`.
pub fn disparity_size(shape: &[usize], path: &Path) -> Result<(usize, usize)> {
    match shape {
        [h, w] | [1, h, w] | [h, w, 1] => Ok((*w, *h)),
        s => Err(Error::format(path, format!("npy disparity must be (H, W), (1, H, W) or (H, W, 1), found {s:?}"))),
    }
}

/// Writes a disparity map as a `(H, W)` `float32` `.npy`.
pub fn write_npy_disparity(path: impl AsRef<Path>, disp: &DisparityMap) -> Result<()> {
    let arr = NpyArray { shape: vec![disp.height, disp.width], data: disp.data.clone() };
    write_npy(path, &arr, NpyDtype::F32)
}
