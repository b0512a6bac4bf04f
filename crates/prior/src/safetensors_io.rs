//! Reading and writing small float32 safetensors files (reference activations, the prior cache).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use dgstereo_core::{Error, Result};
use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};

/// A float32 array: its shape and row-major values.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatArray {
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub values: Vec<f32>,
}

/// Reads every tensor of a safetensors file as float32 (F32, F64 and F16 are accepted).
pub fn read_float_tensors(path: &Path) -> Result<BTreeMap<String, FloatArray>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let file = SafeTensors::deserialize(&bytes).map_err(|e| Error::format(path, e.to_string()))?;
    let mut out = BTreeMap::new();
    for (name, view) in file.tensors() {
        let data = view.data();
        let values: Vec<f32> = match view.dtype() {
            Dtype::F32 => data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            Dtype::F64 => {
                data.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32).collect()
            }
            Dtype::F16 => data.chunks_exact(2).map(|b| f16_to_f32(u16::from_le_bytes([b[0], b[1]]))).collect(),
            other => return Err(Error::format(path, format!("tensor '{name}' has dtype {other:?}, expected a float"))),
        };
        out.insert(name, FloatArray { shape: view.shape().to_vec(), values });
    }
    Ok(out)
}

/// Writes float32 tensors (and string metadata) to a safetensors file.
pub fn write_float_tensors(
    path: &Path,
    tensors: &BTreeMap<String, FloatArray>,
    metadata: Option<HashMap<String, String>>,
) -> Result<()> {
    let bytes: Vec<(String, Vec<u8>, Vec<usize>)> = tensors
        .iter()
        .map(|(k, a)| (k.clone(), a.values.iter().flat_map(|v| v.to_le_bytes()).collect(), a.shape.clone()))
        .collect();
    let views: Vec<(String, TensorView<'_>)> = bytes
        .iter()
        .map(|(k, b, s)| {
            TensorView::new(Dtype::F32, s.clone(), b)
                .map(|v| (k.clone(), v))
                .map_err(|e| Error::format(path, e.to_string()))
        })
        .collect::<Result<_>>()?;
    let serialized = safetensors::serialize(views, &metadata).map_err(|e| Error::format(path, e.to_string()))?;
    std::fs::write(path, serialized).map_err(|e| Error::io(path, e))
}

/// IEEE half to single precision.
fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exponent = ((h >> 10) & 0x1f) as i32;
    let mantissa = (h & 0x3ff) as f32;
    match exponent {
        0 => sign * mantissa * 2f32.powi(-24),
        31 if mantissa == 0.0 => sign * f32::INFINITY,
        31 => f32::NAN,
        e => sign * (1.0 + mantissa / 1024.0) * 2f32.powi(e - 15),
    }
}
