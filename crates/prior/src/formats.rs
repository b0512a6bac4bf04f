//! Readers (and writers, for tests and exports) of single-channel maps: `.npy`, `.pfm`, `.png`.
//!
//! The `.npy` and `.pfm` bytes are the workspace's one codec's (`dgstereo-formats`, below this
//! stage and the data crate alike); this file says what a prior map is: NumPy arrays of any
//! dtype that codec reads whose shape is `(H, W)` up to leading/trailing 1s; PFM in either byte
//! order (`Pf` grey, or `PF` colour, first channel); PNG grey at 16 or 8 bits, the stored
//! integer taken as the value (the scale of a relative prior does not matter).

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_formats::{npy, pfm};

/// A single-channel map, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `height · width` values, row-major, top row first.
    pub values: Vec<f32>,
}

/// The extensions [`read_depth_map`] understands, in the order the file provider probes them.
pub const EXTENSIONS: [&str; 3] = ["npy", "pfm", "png"];

/// Reads a map, choosing the reader by the file's extension.
pub fn read_depth_map(path: &Path) -> Result<DepthMap> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("npy") => read_npy(path),
        Some("pfm") => read_pfm(path),
        Some("png") => read_png(path),
        _ => Err(Error::format(path, "unknown prior file type (expected .npy, .pfm or .png)")),
    }
}

/// Reads a `.npy` file holding a 2-D array (extra axes of length 1 allowed), of any dtype the
/// workspace's codec reads ([`dgstereo_formats::npy`]).
pub fn read_npy(path: &Path) -> Result<DepthMap> {
    let array = npy::read_npy(path)?;
    let mut dims = array.shape.as_slice();
    while dims.len() > 2 && dims[0] == 1 {
        dims = &dims[1..];
    }
    while dims.len() > 2 && dims[dims.len() - 1] == 1 {
        dims = &dims[..dims.len() - 1];
    }
    let &[height, width] = dims else {
        return Err(Error::format(path, format!("npy: shape {:?} is not a single 2-D map", array.shape)));
    };
    Ok(DepthMap { height, width, values: array.data })
}

/// Writes a map as a little-endian float32 `.npy` of shape `(H, W)`.
pub fn write_npy(path: &Path, map: &DepthMap) -> Result<()> {
    let array = npy::NpyArray { shape: vec![map.height, map.width], data: map.values.clone() };
    npy::write_npy(path, &array, npy::NpyDtype::F32)
}

/// Reads a `.pfm` file (first channel of colour files).
pub fn read_pfm(path: &Path) -> Result<DepthMap> {
    let map = pfm::read_pfm(path)?;
    let values = map.data.chunks_exact(map.channels).map(|c| c[0]).collect();
    Ok(DepthMap { height: map.height, width: map.width, values })
}

/// Writes a map as a little-endian grey `.pfm`.
pub fn write_pfm(path: &Path, map: &DepthMap) -> Result<()> {
    let file = pfm::Pfm { width: map.width, height: map.height, channels: 1, data: map.values.clone() };
    pfm::write_pfm(path, &file, pfm::Endian::Little)
}

/// Reads a grey `.png` (16 or 8 bits); the values are the stored integers.
pub fn read_png(path: &Path) -> Result<DepthMap> {
    let image = image::open(path).map_err(|e| Error::format(path, format!("png: {e}")))?;
    let (width, height) = (image.width() as usize, image.height() as usize);
    let values = match image {
        image::DynamicImage::ImageLuma16(g) => g.into_raw().into_iter().map(f32::from).collect(),
        image::DynamicImage::ImageLuma8(g) => g.into_raw().into_iter().map(f32::from).collect(),
        other => {
            return Err(Error::format(
                path,
                format!("png: a prior must be one grey channel, found {:?}", other.color()),
            ));
        }
    };
    Ok(DepthMap { height, width, values })
}

/// Writes a map as a 16-bit grey `.png`, values rounded and clamped to `0..=65535`.
pub fn write_png16(path: &Path, map: &DepthMap) -> Result<()> {
    let raw: Vec<u16> = map.values.iter().map(|v| v.round().clamp(0.0, 65535.0) as u16).collect();
    let buffer = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(map.width as u32, map.height as u32, raw)
        .ok_or_else(|| Error::format(path, "png: size does not match the values"))?;
    buffer.save(path).map_err(|e| Error::format(path, format!("png: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> DepthMap {
        let (height, width) = (5, 7);
        DepthMap { height, width, values: (0..35).map(|i| (i * 37 % 101) as f32 * 3.0 + 1.0).collect() }
    }

    #[test]
    fn formats_round_trip_and_keep_row_order() {
        let dir = std::env::temp_dir().join(format!("dgstereo-prior-formats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let map = sample();
        for (ext, write) in
            [("npy", write_npy as fn(&Path, &DepthMap) -> Result<()>), ("pfm", write_pfm), ("png", write_png16)]
        {
            let path = dir.join(format!("m.{ext}"));
            write(&path, &map).unwrap();
            let back = read_depth_map(&path).unwrap();
            assert_eq!(back, map, "{ext}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn npy_maps_drop_unit_axes_and_refuse_cubes() {
        let dir = std::env::temp_dir().join(format!("dgstereo-prior-npy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, shape: Vec<usize>| {
            let n = shape.iter().product::<usize>();
            let p = dir.join(name);
            let array = npy::NpyArray { shape, data: (0..n).map(|i| i as f32).collect() };
            npy::write_npy(&p, &array, npy::NpyDtype::F64).unwrap();
            p
        };
        let m = read_npy(&write("a.npy", vec![1, 2, 3, 1])).unwrap();
        assert_eq!((m.height, m.width, m.values.len()), (2, 3, 6));
        let err = read_npy(&write("d.npy", vec![2, 2, 2])).unwrap_err().to_string();
        assert!(err.contains("d.npy") && err.contains("2-D"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
