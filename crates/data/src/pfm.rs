//! PFM disparity maps, on the workspace's one PFM codec ([`dgstereo_formats::pfm`], re-exported
//! here).

use std::path::Path;

use dgstereo_core::Result;
pub use dgstereo_formats::pfm::*;

use crate::image::DisparityMap;

/// Reads a PFM as a disparity map: `Pf` as is, `PF` by its first channel (SceneFlow stores
/// disparity as `Pf`; some tools write three equal channels). Values are kept, inf included.
pub fn read_pfm_disparity(path: impl AsRef<Path>) -> Result<DisparityMap> {
    let pfm = read_pfm(path)?;
    let data = if pfm.channels == 1 { pfm.data } else { pfm.data.chunks_exact(pfm.channels).map(|c| c[0]).collect() };
    Ok(DisparityMap { width: pfm.width, height: pfm.height, data })
}

/// Writes a disparity map as a little-endian grayscale (`Pf`) PFM.
pub fn write_pfm_disparity(path: impl AsRef<Path>, disp: &DisparityMap) -> Result<()> {
    let pfm = Pfm { width: disp.width, height: disp.height, channels: 1, data: disp.data.clone() };
    write_pfm(path, &pfm, Endian::Little)
}
