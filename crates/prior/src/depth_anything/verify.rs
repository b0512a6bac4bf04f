//! Conformance check of the burn Depth Anything V2 against activations of the official code.
//!
//! The reference file is a safetensors file with the normalised input `input.image` and the
//! tensors the official PyTorch model computes from it (`encoder.layer.{0..3}.tokens`,
//! `encoder.layer.{0..3}.cls`, `output.depth`; see `shared/golden/README.md`). Each is compared
//! by its largest absolute error; a tensor passes when that error is at most
//! [`RELATIVE_TOLERANCE`] times the reference tensor's range (max - min). The depth line is what
//! the CLI prints last.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, Result};

use super::dinov2::PATCH_SIZE;
use super::{DepthAnythingV2, DepthAnythingV2Encoder};
use crate::safetensors_io::{FloatArray, read_float_tensors};

/// Largest error allowed, relative to the reference tensor's range.
pub const RELATIVE_TOLERANCE: f32 = 1e-3;
/// The key of the network input in the reference file.
pub const INPUT_KEY: &str = "input.image";
/// The key of the depth output in the reference file.
pub const DEPTH_KEY: &str = "output.depth";

/// The comparison of one reference tensor.
#[derive(Debug, Clone, PartialEq)]
pub struct TensorComparison {
    /// Key in the reference file.
    pub key: String,
    /// Shape of the reference tensor.
    pub shape: Vec<usize>,
    /// Largest absolute difference.
    pub max_abs_error: f32,
    /// Range (max - min) of the reference tensor.
    pub reference_range: f32,
    /// Whether `max_abs_error <= RELATIVE_TOLERANCE · reference_range`.
    pub passed: bool,
}

/// The result of [`verify_depth_anything_v2`].
#[derive(Debug, Clone, PartialEq)]
pub struct VerificationReport {
    /// The checkpoint.
    pub weights: PathBuf,
    /// The reference activations.
    pub reference: PathBuf,
    /// The encoder size read from the checkpoint.
    pub encoder: DepthAnythingV2Encoder,
    /// One entry per compared tensor, in the reference file's key order.
    pub comparisons: Vec<TensorComparison>,
    /// Largest absolute error of `output.depth`.
    pub depth_max_abs_error: f32,
    /// Whether every tensor is within tolerance.
    pub passed: bool,
}

impl fmt::Display for VerificationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "Depth Anything V2 ({}) {} vs {}", self.encoder, self.weights.display(), self.reference.display())?;
        for c in &self.comparisons {
            writeln!(
                f,
                "{} {:?}: max abs error {:.3e} (range {:.3e}, relative {:.3e}) {}",
                c.key,
                c.shape,
                c.max_abs_error,
                c.reference_range,
                c.max_abs_error / c.reference_range.max(f32::MIN_POSITIVE),
                if c.passed { "ok" } else { "FAILED" }
            )?;
        }
        writeln!(
            f,
            "tolerance: {RELATIVE_TOLERANCE:e} of each tensor's range; {}",
            if self.passed { "PASSED" } else { "FAILED" }
        )?;
        write!(f, "depth max abs error: {:e}", self.depth_max_abs_error)
    }
}

/// A shape without its axes of length 1 (the reference and the model differ only in those).
fn squeezed(shape: &[usize]) -> Vec<usize> {
    shape.iter().copied().filter(|&d| d != 1).collect()
}

fn compare(key: &str, reference: &FloatArray, ours: Tensor<4>, path: &Path) -> Result<TensorComparison> {
    let our_shape = ours.dims();
    if squeezed(&our_shape) != squeezed(&reference.shape) {
        return Err(Error::format(
            path,
            format!("'{key}' has shape {:?} but the model gives {our_shape:?}", reference.shape),
        ));
    }
    let ours = to_vec(ours);
    let max_abs_error = ours
        .iter()
        .zip(&reference.values)
        .map(|(a, b)| if a.is_finite() { (a - b).abs() } else { f32::INFINITY })
        .fold(0.0, f32::max);
    let (lo, hi) =
        reference.values.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let reference_range = (hi - lo).max(0.0);
    Ok(TensorComparison {
        key: key.to_string(),
        shape: reference.shape.clone(),
        max_abs_error,
        reference_range,
        passed: max_abs_error <= RELATIVE_TOLERANCE * reference_range,
    })
}

/// Loads `weights` (encoder size read from it), runs it on the reference file's `input.image`,
/// and compares every other tensor of `reference`.
///
/// # Errors
/// When a file cannot be read, the checkpoint does not fit (the key is named), or the reference
/// holds a key the model does not produce or of another size.
pub fn verify_depth_anything_v2(weights: &Path, reference: &Path, device: &Device) -> Result<VerificationReport> {
    // The reference is checked first: it is cheap to read, the checkpoint is not.
    let tensors = read_float_tensors(reference)?;
    if !tensors.contains_key(DEPTH_KEY) {
        return Err(Error::format(reference, format!("missing key '{DEPTH_KEY}'")));
    }
    let input = tensors.get(INPUT_KEY).ok_or_else(|| Error::format(reference, format!("missing key '{INPUT_KEY}'")))?;
    let &[n, c, h, w] = input.shape.as_slice() else {
        return Err(Error::format(
            reference,
            format!("'{INPUT_KEY}' has shape {:?}, expected [N, 3, H, W]", input.shape),
        ));
    };
    if c != 3 || h % PATCH_SIZE != 0 || w % PATCH_SIZE != 0 || h == 0 || w == 0 {
        return Err(Error::format(
            reference,
            format!(
                "'{INPUT_KEY}' has shape {:?}, expected [N, 3, H, W] with H, W multiples of {PATCH_SIZE}",
                input.shape
            ),
        ));
    }
    let model = DepthAnythingV2::load_detect_encoder(weights, device)?;
    let x = Tensor::<4>::from_data(TensorData::new(input.values.clone(), [n, c, h, w]), device);
    let output = model.forward_with_layers(x);

    let mut ours: BTreeMap<String, Tensor<4>> = BTreeMap::new();
    for (i, layer) in output.layers.iter().enumerate() {
        ours.insert(format!("encoder.layer.{i}.tokens"), layer.tokens.clone().unsqueeze());
        ours.insert(format!("encoder.layer.{i}.cls"), layer.cls.clone().unsqueeze());
    }
    ours.insert(DEPTH_KEY.to_string(), output.depth);

    let mut comparisons = Vec::new();
    for (key, reference_tensor) in tensors.iter().filter(|(k, _)| k.as_str() != INPUT_KEY) {
        let mine = ours
            .remove(key)
            .ok_or_else(|| Error::format(reference, format!("key '{key}' is not an output of the model")))?;
        comparisons.push(compare(key, reference_tensor, mine, reference)?);
    }
    let depth_max_abs_error =
        comparisons.iter().find(|c| c.key == DEPTH_KEY).map(|c| c.max_abs_error).unwrap_or(f32::INFINITY);
    let passed = comparisons.iter().all(|c| c.passed);
    Ok(VerificationReport {
        weights: weights.to_path_buf(),
        reference: reference.to_path_buf(),
        encoder: model.encoder(),
        comparisons,
        depth_max_abs_error,
        passed,
    })
}
