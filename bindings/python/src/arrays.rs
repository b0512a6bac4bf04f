//! NumPy arrays in and out: images, float maps and masks.
//!
//! Inputs are read through `ndarray` views, so any strides work (C or Fortran order, slices,
//! negative steps) and nothing is copied on the Python side. Images are `HxW` (grey, repeated
//! into the three channels), `HxWx3` or `HxWx4` (alpha dropped), in the channel order the caller
//! names ([`Channels`]), `uint8`, `float32` or `float64` in 0..255, or `uint16` in 0..65535
//! (read as the command line reads a 16-bit file, [`dgstereo_data::image::sample_from_16_bits`]);
//! the pure-Python layer converts other dtypes first. Every check happens here, before the
//! library sees the data, and fails with a `dgstereo.InputError` naming the argument.

use dgstereo_data::{DisparityMap, Mask, RgbImage};
use numpy::ndarray::{Array2, Array3, ArrayView3, ArrayViewD, Axis, Ix3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArrayDyn};
use pyo3::prelude::*;

use crate::errors::input;

/// The dtypes maps are read in.
const DTYPES: &str = "uint8, float32 or float64";

/// The dtypes images are read in.
const IMAGE_DTYPES: &str = "uint8, uint16, float32 or float64";

/// The order of an image's three colour channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channels {
    /// Red, green, blue (what the model takes, and what `dgstereo.read_image` gives).
    Rgb,
    /// Blue, green, red (OpenCV's order).
    Bgr,
}

impl Channels {
    /// Parses `channels="rgb"|"bgr"`.
    pub fn parse(s: &str) -> PyResult<Self> {
        match s.to_ascii_lowercase().as_str() {
            "rgb" => Ok(Self::Rgb),
            "bgr" => Ok(Self::Bgr),
            _ => Err(input(format!("`channels` '{s}': expected \"rgb\" or \"bgr\" (OpenCV's order)"))),
        }
    }

    /// The input channel that holds RGB channel `ch` (of 3 or 4 channels).
    fn source(self, ch: usize) -> usize {
        match self {
            Self::Rgb => ch,
            Self::Bgr => 2 - ch,
        }
    }
}

/// An `HxWx3` (or `HxWx4`, or `HxW`) array whose channels are in `order` as an RGB image; `what`
/// names the argument in errors.
pub fn image(obj: &Bound<'_, PyAny>, what: &str, order: Channels) -> PyResult<RgbImage> {
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        return image_from_view(a.as_array(), f32::from, what, order);
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, u16>>() {
        return image_from_view(a.as_array(), dgstereo_data::image::sample_from_16_bits, what, order);
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        return image_from_view(a.as_array(), |v| v, what, order);
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        return image_from_view(a.as_array(), |v| v as f32, what, order);
    }
    Err(input(format!("`{what}`: expected a NumPy array of {IMAGE_DTYPES}, got {}", describe(obj))))
}

/// A 2-D float array as a map (non-finite values allowed: "unknown").
pub fn map(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<DisparityMap> {
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        return map_from_view(a.as_array(), |v| v, what);
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        return map_from_view(a.as_array(), |v| v as f32, what);
    }
    if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        return map_from_view(a.as_array(), f32::from, what);
    }
    Err(input(format!("`{what}`: expected a 2-D NumPy array of {DTYPES}, got {}", describe(obj))))
}

/// A 2-D boolean array as a mask.
pub fn mask(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Mask> {
    let a = obj
        .extract::<PyReadonlyArrayDyn<'_, bool>>()
        .map_err(|_| input(format!("`{what}`: expected a 2-D NumPy array of bool, got {}", describe(obj))))?;
    let v = a.as_array();
    let (h, w) = shape_2d(&v, what)?;
    Ok(Mask { width: w, height: h, data: v.iter().copied().collect() })
}

/// A map as an `HxW` `float32` array.
pub fn map_to_array<'py>(py: Python<'py>, m: DisparityMap) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let a = Array2::from_shape_vec((m.height, m.width), m.data).map_err(|e| input(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// A mask as an `HxW` `bool` array.
pub fn mask_to_array<'py>(py: Python<'py>, m: Mask) -> PyResult<Bound<'py, PyArray2<bool>>> {
    let a = Array2::from_shape_vec((m.height, m.width), m.data).map_err(|e| input(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// An image as an `HxWx3` `float32` array (0..255).
pub fn image_to_array<'py>(py: Python<'py>, img: &RgbImage) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let a =
        Array3::from_shape_vec((img.height, img.width, 3), img.to_interleaved()).map_err(|e| input(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// `HxWxC` interleaved samples as an `HxWxC` `float32` array.
pub fn interleaved_to_array<'py>(
    py: Python<'py>,
    (h, w, c): (usize, usize, usize),
    data: Vec<f32>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let a = Array3::from_shape_vec((h, w, c), data).map_err(|e| input(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// What an object is, for errors: an array's dtype and shape, else its type.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    let attr = |name: &str| obj.getattr(name).and_then(|v| v.str().map(|s| s.to_string())).ok();
    match (attr("dtype"), attr("shape")) {
        (Some(dtype), Some(shape)) => format!("an array of {dtype} with shape {shape}"),
        _ => obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "an object".into()),
    }
}

fn shape_2d<T>(v: &ArrayViewD<'_, T>, what: &str) -> PyResult<(usize, usize)> {
    match v.shape() {
        &[h, w] if h > 0 && w > 0 => Ok((h, w)),
        &[_, _] => Err(input(format!("`{what}` is empty (shape {:?})", v.shape()))),
        s => Err(input(format!("`{what}`: expected an HxW array, got shape {s:?}"))),
    }
}

fn map_from_view<T: Copy>(v: ArrayViewD<'_, T>, f: impl Fn(T) -> f32, what: &str) -> PyResult<DisparityMap> {
    let (h, w) = shape_2d(&v, what)?;
    // `iter` walks in logical (row-major) order whatever the strides.
    Ok(DisparityMap { width: w, height: h, data: v.iter().map(|x| f(*x)).collect() })
}

fn image_from_view<T: Copy>(
    v: ArrayViewD<'_, T>,
    f: impl Fn(T) -> f32,
    what: &str,
    order: Channels,
) -> PyResult<RgbImage> {
    let v3: ArrayView3<'_, T> = match v.ndim() {
        2 => v.insert_axis(Axis(2)).into_dimensionality::<Ix3>(),
        3 => v.into_dimensionality::<Ix3>(),
        _ => return Err(input(format!("`{what}`: expected an HxWx3 or HxW array, got shape {:?}", v.shape()))),
    }
    .map_err(|e| input(format!("`{what}`: {e}")))?;
    let (h, w, c) = v3.dim();
    // RGBA drops its alpha, as the command line does when it reads an RGBA file.
    if c != 1 && c != 3 && c != 4 {
        return Err(input(format!(
            "`{what}`: expected 3 colour channels (HxWx3, or HxWx4 whose alpha is dropped) or a grey HxW image, got shape ({h}, {w}, {c})"
        )));
    }
    if h == 0 || w == 0 {
        return Err(input(format!("`{what}` is empty (shape ({h}, {w}, {c}))")));
    }
    let mut img = RgbImage::new(w, h);
    for ch in 0..3 {
        let src = v3.index_axis(Axis(2), if c == 1 { 0 } else { order.source(ch) });
        let plane = img.plane_mut(ch);
        for (dst, s) in plane.iter_mut().zip(src.iter()) {
            *dst = f(*s);
        }
    }
    if let Some(i) = img.data.iter().position(|x| !x.is_finite()) {
        let (ch, rest) = (i / (w * h), i % (w * h));
        return Err(input(format!(
            "`{what}` holds a non-finite value ({}) at row {}, column {}, channel {ch}",
            img.data[i],
            rest / w,
            rest % w
        )));
    }
    Ok(img)
}
