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

/// The `(width, height)` of a KITTI disparity PNG, read from its chunks without decoding: the
/// header must say 16-bit grayscale or RGB (what [`read_kitti_png`] reads), and every chunk up to
/// `IEND` must lie within the file, so a truncated file is an error here.
pub fn read_kitti_png_size(path: impl AsRef<Path>) -> Result<(usize, usize)> {
    use std::io::{Read, Seek, SeekFrom};
    let path = path.as_ref();
    let err = |m: String| Error::format(path, format!("PNG: {m}"));
    let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let length = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut read = |at: u64, buf: &mut [u8]| -> Result<()> {
        file.seek(SeekFrom::Start(at)).and_then(|_| file.read_exact(buf)).map_err(|e| Error::io(path, e))
    };
    let mut signature = [0u8; 8];
    if length < 8 {
        return Err(err(format!("truncated: {length} bytes, not even a signature")));
    }
    read(0, &mut signature)?;
    if signature != *b"\x89PNG\r\n\x1a\n" {
        return Err(err("not a PNG file (bad signature)".into()));
    }
    let (mut at, mut size) = (8u64, None);
    loop {
        if at + 12 > length {
            return Err(err(format!("truncated: the file ends at byte {length}, before its IEND chunk")));
        }
        let mut head = [0u8; 8];
        read(at, &mut head)?;
        let data = u64::from(u32::from_be_bytes([head[0], head[1], head[2], head[3]]));
        let end = at + 12 + data;
        if end > length {
            let kind = String::from_utf8_lossy(&head[4..]);
            return Err(err(format!(
                "truncated: the {kind} chunk at byte {at} needs {} bytes, the file has {}",
                12 + data,
                length - at
            )));
        }
        match &head[4..] {
            b"IHDR" if data >= 13 => {
                let mut ihdr = [0u8; 13];
                read(at + 8, &mut ihdr)?;
                let width = u32::from_be_bytes([ihdr[0], ihdr[1], ihdr[2], ihdr[3]]) as usize;
                let height = u32::from_be_bytes([ihdr[4], ihdr[5], ihdr[6], ihdr[7]]) as usize;
                let (depth, colour) = (ihdr[8], ihdr[9]);
                if depth != 16 || !matches!(colour, 0 | 2) {
                    return Err(Error::format(
                        path,
                        format!(
                            "KITTI disparity PNG must be 16-bit grayscale, found {depth}-bit {}",
                            match colour {
                                0 => "grayscale",
                                2 => "RGB",
                                3 => "palette",
                                4 => "grayscale with alpha",
                                _ => "RGBA",
                            }
                        ),
                    ));
                }
                size = Some((width, height));
            }
            b"IEND" => break,
            _ => {}
        }
        at = end;
    }
    size.ok_or_else(|| err("no IHDR chunk".into()))
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
