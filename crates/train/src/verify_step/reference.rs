//! The reference file of two training steps: its tensors, scalars and metadata, and its batch.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use burn::tensor::Device;
use dgstereo_core::tensor::from_vec;
use dgstereo_core::{Error, Result};
use dgstereo_loss::LossTarget;
use safetensors::{Dtype, SafeTensors};

use crate::batch::TensorBatch;

/// A float32 tensor of the reference: its shape and values.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceTensor {
    /// The shape.
    pub shape: Vec<usize>,
    /// The values, row-major.
    pub values: Vec<f32>,
}

/// Prefix of the gradients before clipping of step 1 (`step1.grad.<official name>`).
pub const GRADIENT_PREFIX: &str = "step1.grad.";
/// Prefix of the parameters after step 2 (`step2.param.<official name>`).
pub const PARAMETER_PREFIX: &str = "step2.param.";

/// The contents of a `*.train_step.safetensors` file (see the golden README): the batch, the
/// predictions of step 1, losses, gradient norms and learning rates of both steps (float64
/// scalars), some gradients and parameters, and the run's settings in the metadata.
#[derive(Debug, Clone)]
pub struct TrainStepReference {
    /// The file it was read from (named in errors).
    pub path: PathBuf,
    /// Float32 tensors by key.
    pub tensors: BTreeMap<String, ReferenceTensor>,
    /// Float64 scalars by key (`step1.loss`, ...).
    pub scalars: BTreeMap<String, f64>,
    /// The metadata (`iters`, `num_steps`, `lr`, `config`, ...).
    pub metadata: BTreeMap<String, String>,
}

impl TrainStepReference {
    /// Reads a reference file; fails naming the file when it is not safetensors or holds a
    /// dtype other than float32 tensors and float64 scalars.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let not_safetensors =
            |e: safetensors::SafeTensorError| Error::format(path, format!("not a safetensors file: {e}"));
        let (_, header) = SafeTensors::read_metadata(&bytes).map_err(not_safetensors)?;
        let metadata = header.metadata().clone().unwrap_or_default().into_iter().collect();
        let st = SafeTensors::deserialize(&bytes).map_err(not_safetensors)?;
        let mut tensors = BTreeMap::new();
        let mut scalars = BTreeMap::new();
        for (name, view) in st.tensors() {
            match view.dtype() {
                Dtype::F32 => {
                    let values =
                        view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
                    tensors.insert(name, ReferenceTensor { shape: view.shape().to_vec(), values });
                }
                Dtype::F64 if view.shape().iter().product::<usize>() == 1 => {
                    let b: [u8; 8] = view.data()[..8].try_into().expect("a one-element float64 tensor has 8 bytes");
                    scalars.insert(name, f64::from_le_bytes(b));
                }
                other => {
                    return Err(Error::format(
                        path,
                        format!(
                            "{name}: expected a float32 tensor or a float64 scalar, found {other:?} {:?}",
                            view.shape()
                        ),
                    ));
                }
            }
        }
        Ok(Self { path: path.to_path_buf(), tensors, scalars, metadata })
    }

    /// The tensor `key`; fails naming the file and the key when it is absent.
    pub fn tensor(&self, key: &str) -> Result<&ReferenceTensor> {
        self.tensors.get(key).ok_or_else(|| Error::format(&self.path, format!("missing tensor '{key}'")))
    }

    /// The float64 scalar `key`.
    pub fn scalar(&self, key: &str) -> Result<f64> {
        self.scalars.get(key).copied().ok_or_else(|| Error::format(&self.path, format!("missing scalar '{key}'")))
    }

    /// The metadata entry `key`, parsed.
    pub fn meta<T: FromStr>(&self, key: &str) -> Result<T> {
        let text = self
            .metadata
            .get(key)
            .ok_or_else(|| Error::format(&self.path, format!("missing metadata entry '{key}'")))?;
        text.trim()
            .parse()
            .map_err(|_| Error::format(&self.path, format!("metadata entry '{key}' = '{text}' is not a valid value")))
    }

    /// The official parameter names of the keys under `prefix` ([`GRADIENT_PREFIX`],
    /// [`PARAMETER_PREFIX`]), in key order.
    pub fn names_under(&self, prefix: &str) -> Vec<String> {
        self.tensors.keys().filter_map(|k| k.strip_prefix(prefix)).map(str::to_string).collect()
    }

    /// The number of iterations of step 1 whose predictions the file holds
    /// (`step1.flow_up.{0..}`).
    pub fn prediction_count(&self) -> usize {
        (0..).take_while(|k| self.tensors.contains_key(&format!("step1.flow_up.{k}"))).count()
    }

    /// The batch as the trainer takes it, on `device`: images as stored, positive disparity
    /// (`-input.flow_gt`) as both ground truths, `input.valid` as the validity map. Pixels whose
    /// ground truth is not finite are invalid and hold 0, as in [`crate::batch::to_tensors`].
    ///
    /// # Shapes
    /// - `input.left`, `input.right`: `[N, 3, H, W]`; `input.flow_gt`: `[N, 1, H, W]`;
    ///   `input.valid`: `[N, H, W]`
    pub fn batch(&self, device: &Device) -> Result<TensorBatch> {
        let left = self.tensor("input.left")?;
        let right = self.tensor("input.right")?;
        let flow = self.tensor("input.flow_gt")?;
        let valid = self.tensor("input.valid")?;
        let [n, c, h, w] = four(&left.shape).filter(|s| s[1] == 3).ok_or_else(|| {
            Error::format(&self.path, format!("input.left: expected [N, 3, H, W], found {:?}", left.shape))
        })?;
        let expect = |key: &str, t: &ReferenceTensor, shape: &[usize]| {
            if t.shape == shape {
                Ok(())
            } else {
                Err(Error::format(&self.path, format!("{key}: expected {shape:?}, found {:?}", t.shape)))
            }
        };
        expect("input.right", right, &[n, c, h, w])?;
        expect("input.flow_gt", flow, &[n, 1, h, w])?;
        expect("input.valid", valid, &[n, h, w])?;
        let (disparity, valid): (Vec<f32>, Vec<f32>) = flow
            .values
            .iter()
            .zip(&valid.values)
            .map(|(&f, &v)| if v >= 0.5 && f.is_finite() { (-f, 1.0) } else { (0.0, 0.0) })
            .unzip();
        let disparity = from_vec(disparity, [n, 1, h, w], device);
        Ok(TensorBatch {
            left: from_vec(left.values.clone(), [n, c, h, w], device),
            right: from_vec(right.values.clone(), [n, c, h, w], device),
            target: LossTarget {
                disparity_bilinear: disparity.clone(),
                disparity_nearest: disparity,
                valid: from_vec(valid, [n, 1, h, w], device),
            },
            names: (0..n).map(|i| format!("{}[{i}]", self.path.display())).collect(),
        })
    }
}

fn four(shape: &[usize]) -> Option<[usize; 4]> {
    shape.try_into().ok()
}
