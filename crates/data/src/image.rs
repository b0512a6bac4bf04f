//! Plain image containers: [`RgbImage`] (planar CHW `f32`, 0..255), [`DisparityMap`] and [`Mask`],
//! with loading and saving of PNG/JPEG/BMP/TIFF pictures.

use std::path::Path;

use dgstereo_core::{Error, Result};

/// An RGB image stored planar, channel-major (`CHW`), as `f32` in `0..=255`.
///
/// # Layout
/// `data.len() == 3 * height * width`; the sample of channel `c` at column `x`, row `y` is
/// `data[(c * height + y) * width + x]`. This is the layout of one image of the model's
/// `[N, 3, H, W]` input tensor, so `data` can be handed over without reordering.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Samples, `CHW`, 0..255.
    pub data: Vec<f32>,
}

impl RgbImage {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, data: vec![0.0; 3 * width * height] }
    }

    /// An image whose pixel `(x, y)` is `f(x, y)` (`[r, g, b]`).
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> [f32; 3]) -> Self {
        let mut img = Self::new(width, height);
        for y in 0..height {
            for x in 0..width {
                img.set(x, y, f(x, y));
            }
        }
        img
    }

    /// Builds an image from interleaved `HWC` samples (`[r, g, b, r, g, b, ...]`).
    pub fn from_interleaved(width: usize, height: usize, hwc: &[f32]) -> Result<Self> {
        if hwc.len() != 3 * width * height {
            return Err(Error::Shape(format!(
                "interleaved RGB of {width}x{height} needs {} samples, got {}",
                3 * width * height,
                hwc.len()
            )));
        }
        Ok(Self::from_fn(width, height, |x, y| {
            let i = 3 * (y * width + x);
            [hwc[i], hwc[i + 1], hwc[i + 2]]
        }))
    }

    /// The samples interleaved (`HWC`).
    pub fn to_interleaved(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.data.len());
        for y in 0..self.height {
            for x in 0..self.width {
                out.extend_from_slice(&self.get(x, y));
            }
        }
        out
    }

    /// Number of pixels in one plane.
    pub fn plane_len(&self) -> usize {
        self.width * self.height
    }

    /// The plane of channel `c` (0 = red, 1 = green, 2 = blue).
    pub fn plane(&self, c: usize) -> &[f32] {
        let n = self.plane_len();
        &self.data[c * n..(c + 1) * n]
    }

    /// The mutable plane of channel `c`.
    pub fn plane_mut(&mut self, c: usize) -> &mut [f32] {
        let n = self.plane_len();
        &mut self.data[c * n..(c + 1) * n]
    }

    /// The pixel at `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        let n = self.plane_len();
        let i = y * self.width + x;
        [self.data[i], self.data[n + i], self.data[2 * n + i]]
    }

    /// Sets the pixel at `(x, y)`.
    pub fn set(&mut self, x: usize, y: usize, rgb: [f32; 3]) {
        let n = self.plane_len();
        let i = y * self.width + x;
        self.data[i] = rgb[0];
        self.data[n + i] = rgb[1];
        self.data[2 * n + i] = rgb[2];
    }

    /// The sub-image of `width x height` whose top-left corner is `(x0, y0)`.
    pub fn crop(&self, x0: usize, y0: usize, width: usize, height: usize) -> Result<Self> {
        check_crop(self.width, self.height, x0, y0, width, height)?;
        Ok(Self::from_fn(width, height, |x, y| self.get(x0 + x, y0 + y)))
    }
}

/// A single-channel `f32` map, row-major (`data[y * width + x]`).
///
/// Used for disparity: values in pixels, positive for the left view (`x_right = x_left - d`).
/// Non-finite values (NaN, ±inf) mean "unknown"; readers of formats with another convention
/// (KITTI's 0) keep the file's value and let the dataset's validity rule decide.
#[derive(Clone, Debug, PartialEq)]
pub struct DisparityMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Values, row-major.
    pub data: Vec<f32>,
}

impl DisparityMap {
    /// A map filled with `value`.
    pub fn filled(width: usize, height: usize, value: f32) -> Self {
        Self { width, height, data: vec![value; width * height] }
    }

    /// A map from row-major values; errors if the length does not match.
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Result<Self> {
        if data.len() != width * height {
            return Err(Error::Shape(format!(
                "map of {width}x{height} needs {} values, got {}",
                width * height,
                data.len()
            )));
        }
        Ok(Self { width, height, data })
    }

    /// The value at `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Sets the value at `(x, y)`.
    pub fn set(&mut self, x: usize, y: usize, v: f32) {
        self.data[y * self.width + x] = v;
    }

    /// The pixels whose value is finite and greater than zero (the usual ground-truth rule).
    pub fn valid_positive(&self) -> Mask {
        Mask {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|v| v.is_finite() && *v > 0.0).collect(),
        }
    }

    /// The pixels whose value is finite.
    pub fn valid_finite(&self) -> Mask {
        Mask { width: self.width, height: self.height, data: self.data.iter().map(|v| v.is_finite()).collect() }
    }

    /// The sub-map of `width x height` whose top-left corner is `(x0, y0)`.
    pub fn crop(&self, x0: usize, y0: usize, width: usize, height: usize) -> Result<Self> {
        check_crop(self.width, self.height, x0, y0, width, height)?;
        let mut data = Vec::with_capacity(width * height);
        for y in y0..y0 + height {
            data.extend_from_slice(&self.data[y * self.width + x0..y * self.width + x0 + width]);
        }
        Ok(Self { width, height, data })
    }
}

/// A boolean per-pixel mask, row-major (`data[y * width + x]`); `true` = keep / valid.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Flags, row-major.
    pub data: Vec<bool>,
}

impl Mask {
    /// A mask with every pixel set to `value`.
    pub fn filled(width: usize, height: usize, value: bool) -> Self {
        Self { width, height, data: vec![value; width * height] }
    }

    /// The flag at `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> bool {
        self.data[y * self.width + x]
    }

    /// Number of `true` pixels.
    pub fn count(&self) -> usize {
        self.data.iter().filter(|b| **b).count()
    }

    /// Pixel-wise AND of two masks of equal size.
    pub fn and(&self, other: &Mask) -> Result<Mask> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(Error::Shape(format!(
                "masks of {}x{} and {}x{}",
                self.width, self.height, other.width, other.height
            )));
        }
        Ok(Mask {
            width: self.width,
            height: self.height,
            data: self.data.iter().zip(&other.data).map(|(a, b)| *a && *b).collect(),
        })
    }

    /// The sub-mask of `width x height` whose top-left corner is `(x0, y0)`.
    pub fn crop(&self, x0: usize, y0: usize, width: usize, height: usize) -> Result<Self> {
        check_crop(self.width, self.height, x0, y0, width, height)?;
        let mut data = Vec::with_capacity(width * height);
        for y in y0..y0 + height {
            data.extend_from_slice(&self.data[y * self.width + x0..y * self.width + x0 + width]);
        }
        Ok(Self { width, height, data })
    }
}

fn check_crop(w: usize, h: usize, x0: usize, y0: usize, cw: usize, ch: usize) -> Result<()> {
    if x0 + cw > w || y0 + ch > h {
        return Err(Error::Shape(format!("crop {cw}x{ch} at ({x0}, {y0}) does not fit in {w}x{h}")));
    }
    Ok(())
}

/// Converts an `image` crate error on `path` to [`Error`], keeping I/O errors as I/O.
pub(crate) fn image_error(path: &Path, e: image::ImageError) -> Error {
    match e {
        image::ImageError::IoError(io) => Error::io(path, io),
        other => Error::format(path, other.to_string()),
    }
}

/// Opens and decodes a picture, naming `path` in any error.
pub(crate) fn open_dynamic(path: &Path) -> Result<image::DynamicImage> {
    let reader = image::ImageReader::open(path).map_err(|e| Error::io(path, e))?;
    let reader = reader.with_guessed_format().map_err(|e| Error::io(path, e))?;
    reader.decode().map_err(|e| image_error(path, e))
}

/// A 16-bit sample in 0..255, as [`load_rgb`] reads 16-bit files (and the Python package reads
/// `uint16` arrays): `v · 255 / 65535`.
pub fn sample_from_16_bits(v: u16) -> f32 {
    f32::from(v) * (255.0 / 65535.0)
}

/// Loads any PNG/JPEG/BMP/TIFF picture as RGB `f32` in 0..255.
///
/// Grayscale is replicated to three channels, alpha is dropped; 8-bit samples keep their value
/// exactly, 16-bit samples are scaled by `255 / 65535` ([`sample_from_16_bits`]), float samples
/// by 255.
pub fn load_rgb(path: impl AsRef<Path>) -> Result<RgbImage> {
    let path = path.as_ref();
    let img = open_dynamic(path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    use image::DynamicImage as D;
    let hwc: Vec<f32> = match img {
        D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => {
            img.to_rgb8().into_raw().into_iter().map(f32::from).collect()
        }
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            img.to_rgb16().into_raw().into_iter().map(sample_from_16_bits).collect()
        }
        _ => img.to_rgb32f().into_raw().into_iter().map(|v| v * 255.0).collect(),
    };
    RgbImage::from_interleaved(w, h, &hwc).map_err(|e| Error::format(path, e.to_string()))
}

/// Saves an image as 8-bit RGB (format from the extension: png, jpg, bmp, tif), rounding and
/// clamping samples to 0..255.
pub fn save_rgb(path: impl AsRef<Path>, img: &RgbImage) -> Result<()> {
    let path = path.as_ref();
    let raw: Vec<u8> = img.to_interleaved().iter().map(|v| v.round().clamp(0.0, 255.0) as u8).collect();
    let buf = image::RgbImage::from_raw(img.width as u32, img.height as u32, raw)
        .ok_or_else(|| Error::format(path, "image buffer of the wrong size"))?;
    buf.save(path).map_err(|e| image_error(path, e))
}

/// Loads a mask picture: a pixel is `true` where any channel is non-zero.
pub fn load_mask(path: impl AsRef<Path>) -> Result<Mask> {
    let path = path.as_ref();
    let img = open_dynamic(path)?.to_rgb16();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = img.pixels().map(|p| p.0.iter().any(|v| *v != 0)).collect();
    Ok(Mask { width: w, height: h, data })
}

/// Saves a mask as an 8-bit grayscale PNG (255 = `true`, 0 = `false`).
pub fn save_mask(path: impl AsRef<Path>, mask: &Mask) -> Result<()> {
    let path = path.as_ref();
    let raw: Vec<u8> = mask.data.iter().map(|b| if *b { 255 } else { 0 }).collect();
    let buf = image::GrayImage::from_raw(mask.width as u32, mask.height as u32, raw)
        .ok_or_else(|| Error::format(path, "mask buffer of the wrong size"))?;
    buf.save(path).map_err(|e| image_error(path, e))
}
