//! The module's functions beside the model: metrics, depth, PFM and image files.

use std::path::PathBuf;

use dgstereo_data::pfm::{Endian, Pfm, read_pfm as read_pfm_file, write_pfm as write_pfm_file};
use dgstereo_eval::metrics::{METRIC_NAMES, ValidOptions, evaluate};
use dgstereo_inference::Calibration;
use dgstereo_inference::calibration::Adjustment;
use dgstereo_inference::pointcloud::depth_map;
use nalgebra::Matrix3;
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays;
use crate::errors::{Kind, convert, from_library, input};

/// The metrics of `pred` against `gt` (see `dgstereo.metrics`).
#[pyfunction]
#[pyo3(signature = (pred, gt, mask=None, max_disp=None))]
pub fn metrics<'py>(
    py: Python<'py>,
    pred: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    mask: Option<&Bound<'py, PyAny>>,
    max_disp: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let (p, g) = (arrays::map(pred, "pred")?, arrays::map(gt, "gt")?);
    let m = mask.map(|m| arrays::mask(m, "mask")).transpose()?;
    let result = evaluate(&p, &g, m.as_ref(), ValidOptions { max_disp });
    let values = from_library(result, Kind::Input)?;
    let out = PyDict::new(py);
    for (name, v) in METRIC_NAMES.iter().zip(values.values()) {
        out.set_item(*name, v)?;
    }
    out.set_item("valid_pixels", values.valid_pixels)?;
    Ok(out)
}

/// Depth in metres and the notice of a calibration rescaled to the map's size, if any (see
/// `dgstereo.depth`).
#[pyfunction]
#[pyo3(signature = (disparity, fx=None, baseline=None, doffs=0.0, calib=None, crop=None, scale=None))]
// One argument per keyword of the Python function.
#[allow(clippy::too_many_arguments)]
pub fn depth<'py>(
    py: Python<'py>,
    disparity: &Bound<'py, PyAny>,
    fx: Option<f64>,
    baseline: Option<f64>,
    doffs: f64,
    calib: Option<PathBuf>,
    crop: Option<(f64, f64)>,
    scale: Option<(f64, f64)>,
) -> PyResult<(Bound<'py, PyAny>, Option<String>)> {
    let d = arrays::map(disparity, "disparity")?;
    let adjustment = Adjustment { crop, scale };
    let (calibration, notice) = match (calib, fx, baseline) {
        (Some(path), None, None) => {
            let loaded = from_library(Calibration::load(&path), Kind::Input)?;
            let fitted = loaded.adjusted(&adjustment, d.width, d.height).map_err(|e| match e {
                dgstereo_core::Error::Shape(m) if adjustment.is_none() => {
                    input(format!("{m}: `crop=(x, y)` and/or `scale=`"))
                }
                e => convert(e, Kind::Input),
            })?;
            (fitted.0, fitted.1.map(|n| n.to_string()))
        }
        (None, Some(fx), Some(baseline)) => {
            if !adjustment.is_none() {
                return Err(input("`crop` and `scale` adjust a calibration file: give `calib`"));
            }
            if !(fx.is_finite() && fx > 0.0) {
                return Err(input(format!("`fx` {fx}: the focal length must be a positive number of pixels")));
            }
            if !(baseline.is_finite() && baseline > 0.0) {
                return Err(input(format!("`baseline` {baseline}: must be a positive length in metres")));
            }
            if !doffs.is_finite() {
                return Err(input("`doffs` must be finite"));
            }
            let given = Calibration {
                source: PathBuf::from("<arguments>"),
                intrinsics: Matrix3::new(fx, 0.0, 0.0, 0.0, fx, 0.0, 0.0, 0.0, 1.0),
                baseline_m: baseline,
                doffs,
                size: None,
                depth_range: None,
            };
            (given, None)
        }
        _ => return Err(input("give either `fx` and `baseline` (metres), or `calib` (a calibration file)")),
    };
    Ok((arrays::map_to_array(py, depth_map(&d, &calibration))?.into_any(), notice))
}

/// Reads a PFM file (see `dgstereo.read_pfm`).
#[pyfunction]
pub fn read_pfm<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let pfm = from_library(read_pfm_file(&path), Kind::File)?;
    if pfm.channels == 1 {
        let map = dgstereo_data::DisparityMap { width: pfm.width, height: pfm.height, data: pfm.data };
        return Ok(arrays::map_to_array(py, map)?.into_any());
    }
    Ok(arrays::interleaved_to_array(py, (pfm.height, pfm.width, pfm.channels), pfm.data)?.into_any())
}

/// Writes a PFM file (see `dgstereo.write_pfm`).
#[pyfunction]
pub fn write_pfm(path: PathBuf, array: &Bound<'_, PyAny>) -> PyResult<()> {
    let pfm = match array.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        Ok(a) => {
            let v = a.as_array();
            match v.shape() {
                &[h, w] if h > 0 && w > 0 => {
                    Pfm { width: w, height: h, channels: 1, data: v.iter().copied().collect() }
                }
                &[h, w, 3] if h > 0 && w > 0 => {
                    Pfm { width: w, height: h, channels: 3, data: v.iter().copied().collect() }
                }
                s => return Err(input(format!("`array`: expected HxW or HxWx3, got shape {s:?}"))),
            }
        }
        Err(_) => return Err(input("`array`: expected a float32 NumPy array")),
    };
    from_library(write_pfm_file(&path, &pfm, Endian::Little), Kind::File)
}

/// Reads an image file as `HxWx3` `float32` in 0..255 (see `dgstereo.read_image`).
#[pyfunction]
pub fn read_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let img = from_library(dgstereo_data::load_rgb(&path), Kind::File)?;
    Ok(arrays::image_to_array(py, &img)?.into_any())
}
