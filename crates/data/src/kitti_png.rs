//! KITTI 16-bit PNG disparity: `disparity = value / 256`, value 0 = no ground truth.
//!
//! Reading keeps the file's convention: an invalid pixel reads as `0.0`, which every validity
//! rule of this crate (`d > 0`) rejects. Writing stores `round(d * 256)` clamped to
//! `1..=65535` for finite `d > 0` and 0 for everything else (NaN, inf, `d <= 0`).
//! The same encoding is used by DrivingStereo.

use std::path::Path;

use dgstereo_core::{Error, Result};

use crate::image::{DisparityMap, image_error, open_dynamic};

/// Reads a KITTI-style 16-bit disparity PNG (grayscale; a 16-bit RGB file uses its first channel).
pub fn read_kitti_png(path: impl AsRef<Path>) -> Result<DisparityMap> {
    let path = path.as_ref();
    let img = open_dynamic(path)?;
    use image::DynamicImage as D;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        D::ImageLuma16(buf) => buf.into_raw().into_iter().map(|v| f32::from(v) / 256.0).collect(),
        D::ImageRgb16(buf) => buf.into_raw().chunks_exact(3).map(|c| f32::from(c[0]) / 256.0).collect(),
        other => {
            return Err(Error::format(
                path,
                format!("KITTI disparity PNG must be 16-bit grayscale, found {:?}", other.color()),
            ));
        }
    };
    DisparityMap::from_vec(w, h, data).map_err(|e| Error::format(path, e.to_string()))
}

/// Encodes one disparity value as KITTI's 16-bit integer.
pub fn kitti_encode(d: f32) -> u16 {
    if d.is_finite() && d > 0.0 { (d * 256.0).round().clamp(1.0, 65535.0) as u16 } else { 0 }
}

/// Writes a disparity map as a KITTI 16-bit grayscale PNG.
pub fn write_kitti_png(path: impl AsRef<Path>, disp: &DisparityMap) -> Result<()> {
    let path = path.as_ref();
    let raw: Vec<u16> = disp.data.iter().map(|d| kitti_encode(*d)).collect();
    let buf: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
        image::ImageBuffer::from_raw(disp.width as u32, disp.height as u32, raw)
            .ok_or_else(|| Error::format(path, "disparity buffer of the wrong size"))?;
    buf.save_with_format(path, image::ImageFormat::Png).map_err(|e| image_error(path, e))
}
