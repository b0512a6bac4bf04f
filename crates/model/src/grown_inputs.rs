//! Warm start of convolutions whose input grew: the file's weights on the leading input channels,
//! zero on the new ones.
//!
//! Design decision: when a module gains inputs (the motion encoder's last convolution reads the
//! guidance features after the correlation and flow features), a non-strict load used to leave the
//! whole layer at its random initialisation, so a model started from a trained baseline began by
//! forgetting that layer. Appended inputs are the common case, so the layer instead takes the
//! file's weights on its first channels and zeros on the appended ones: it computes exactly what
//! it computed in the file's model, and training grows the new channels from zero.

use std::collections::HashMap;
use std::path::Path;

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Tensor, TensorData};
use dgstereo_core::{Error, Result};

use crate::RaftStereo;

/// `[O, C, kh, kw]` weights of the file, by parameter path.
type FileWeights = HashMap<String, (Vec<usize>, Vec<f32>)>;

struct GrownInputs<'a> {
    path: Vec<String>,
    file: &'a FileWeights,
    grown: Vec<String>,
}

impl ModuleMapper for GrownInputs<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let key = self.path.join(".");
        let Some((shape, values)) = self.file.get(&key) else { return param };
        let dims = param.val().dims();
        if D != 4 || shape.len() != 4 || shape[0] != dims[0] || shape[2..] != dims[2..] || shape[1] >= dims[1] {
            return param;
        }
        let (o, c_file, c_model, k) = (dims[0], shape[1], dims[1], dims[2] * dims[3]);
        let mut grown = vec![0.0f32; o * c_model * k];
        for oc in 0..o {
            let src = &values[oc * c_file * k..][..c_file * k];
            grown[oc * c_model * k..][..c_file * k].copy_from_slice(src);
        }
        self.grown.push(key);
        let device = param.val().device();
        param.map(|_| Tensor::from_data(TensorData::new(grown, dims), &device))
    }
}

/// For each parameter of `kept` (shape mismatches of a non-strict load) that is a convolution
/// weight with more input channels in `model` than in the safetensors file at `path`, and the same
/// other dimensions: the file's weights on the leading channels, zeros on the rest. Returns the
/// model and the paths so treated.
pub fn warm_start(model: RaftStereo, path: &Path, kept: &[String]) -> Result<(RaftStereo, Vec<String>)> {
    if kept.is_empty() {
        return Ok((model, Vec::new()));
    }
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let st = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| Error::format(path, format!("not a safetensors file: {e}")))?;
    let mut file = FileWeights::new();
    for key in kept {
        let Ok(view) = st.tensor(key) else { continue };
        if view.dtype() != safetensors::Dtype::F32 || view.shape().len() != 4 {
            continue;
        }
        let values = view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        file.insert(key.clone(), (view.shape().to_vec(), values));
    }
    let mut mapper = GrownInputs { path: Vec::new(), file: &file, grown: Vec::new() };
    let model = model.map(&mut mapper);
    let grown = mapper.grown;
    Ok((model, grown))
}
