//! Conformance check against activations computed by the official PyTorch code.
//!
//! A reference file (`../shared/golden/raft_stereo_random.activations.safetensors` and
//! `raft_stereo_realtime_random.activations.safetensors`, made by the official RAFT-Stereo code
//! at commit 6068c1a in float32 on CPU, see its README) holds the inputs and intermediate
//! tensors of a short run. [`verify_raft_stereo`] loads the checkpoint into the architecture its
//! tensors show ([`crate::checkpoint_config`]), runs as many iterations as the file has
//! `iter.K.flow_up` keys, and compares every tensor the file holds: flows within 1e-3 absolute,
//! everything else within 1e-4 relative to the tensor's largest magnitude. The realtime file's
//! names (`fmap.left`, `final.flow_up`, `final.flow_lowres`) are the same tensors as the traced
//! `fnet.left` and the last iteration's flows.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use burn::tensor::{Device, Tensor};
use dgstereo_core::{Error, Result, tensor::from_vec, tensor::to_vec};
use safetensors::SafeTensors;

use crate::{ForwardOptions, Probe, checkpoint_config};

/// Tolerance on flows (absolute, pixels).
pub const FLOW_TOLERANCE: f32 = 1e-3;
/// Tolerance on other tensors (relative to their largest magnitude).
pub const FEATURE_TOLERANCE: f32 = 1e-4;

/// One compared tensor.
#[derive(Debug, Clone)]
pub struct VerifyLine {
    /// Key in the reference file.
    pub key: String,
    /// Its shape.
    pub shape: Vec<usize>,
    /// Largest absolute difference.
    pub max_abs_error: f32,
    /// `max_abs_error` divided by the reference's largest magnitude.
    pub relative_error: f32,
    /// Whether it is within tolerance.
    pub passed: bool,
}

/// The result of a verification.
#[derive(Debug, Clone)]
pub struct VerifyReport {
    /// One line per compared key, in the file's key order.
    pub lines: Vec<VerifyLine>,
    /// Max absolute error of the last iteration's full-resolution flow.
    pub final_flow_error: f32,
    /// Keys of the reference that this implementation does not produce.
    pub unmatched: Vec<String>,
    /// The configuration read from the checkpoint (one line).
    pub configuration: String,
}

impl VerifyReport {
    /// Whether every tensor is within tolerance and every key was compared.
    pub fn passed(&self) -> bool {
        self.unmatched.is_empty() && self.lines.iter().all(|l| l.passed)
    }
}

impl fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "configuration: {}", self.configuration)?;
        // The key column fits the longest key (24 at least, RAFT-Stereo's).
        let width =
            self.lines.iter().map(|l| l.key.len()).chain(self.unmatched.iter().map(String::len)).fold(24, usize::max);
        for l in &self.lines {
            writeln!(
                f,
                "{:<width$} {:<18} max abs error {:.3e}  rel {:.3e}  {}",
                l.key,
                format!("{:?}", l.shape),
                l.max_abs_error,
                l.relative_error,
                if l.passed { "ok" } else { "FAIL" }
            )?;
        }
        for k in &self.unmatched {
            writeln!(f, "{k:<width$} not produced by this implementation  FAIL")?;
        }
        write!(f, "final flow max abs error: {:e}", self.final_flow_error)
    }
}

/// Reference tensors by name: shape and values.
pub type ReferenceTensors = BTreeMap<String, (Vec<usize>, Vec<f32>)>;

/// Reads every float32 tensor of a safetensors file as `(shape, values)`.
pub fn read_reference(path: &Path) -> Result<ReferenceTensors> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let st =
        SafeTensors::deserialize(&bytes).map_err(|e| Error::format(path, format!("not a safetensors file: {e}")))?;
    let mut out = BTreeMap::new();
    for (name, view) in st.tensors() {
        if view.dtype() != safetensors::Dtype::F32 {
            return Err(Error::format(path, format!("{name}: expected float32, found {:?}", view.dtype())));
        }
        let values = view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        out.insert(name, (view.shape().to_vec(), values));
    }
    Ok(out)
}

/// The 4-D tensor `key` of `reference` (read from `path`) on `device`.
pub(crate) fn tensor4(reference: &ReferenceTensors, key: &str, path: &Path, device: &Device) -> Result<Tensor<4>> {
    let (shape, values) = reference.get(key).ok_or_else(|| Error::format(path, format!("missing key '{key}'")))?;
    let shape: [usize; 4] = shape
        .as_slice()
        .try_into()
        .map_err(|_| Error::format(path, format!("{key}: expected 4 dimensions, found {shape:?}")))?;
    Ok(from_vec(values.clone(), shape, device))
}

/// The reference's names for traced tensors that the trace records under another name.
fn aliases(last: usize) -> [(&'static str, String); 4] {
    [
        ("fmap.left", "fnet.left".into()),
        ("fmap.right", "fnet.right".into()),
        ("final.flow_up", format!("iter.{last}.flow_up")),
        ("final.flow_lowres", format!("iter.{last}.flow_lowres")),
    ]
}

/// Runs RAFT-Stereo, in the configuration `weights`' tensors show, on the reference's inputs
/// and compares every tensor the reference holds.
pub fn verify_raft_stereo(weights: &Path, reference: &Path, device: &Device) -> Result<VerifyReport> {
    let refs = read_reference(reference)?;
    let (model, config) = checkpoint_config::load_detected(weights, device)?;
    let left = tensor4(&refs, "input.left", reference, device)?;
    let right = tensor4(&refs, "input.right", reference, device)?;
    let iters = refs.keys().filter(|k| k.starts_with("iter.") && k.ends_with(".flow_up")).count();
    let mut trace = BTreeMap::new();
    let options =
        ForwardOptions { all_iterations: true, probe: Probe::new(Some(&mut trace), None), ..ForwardOptions::default() };
    model.forward_flow(left, right, None, iters, options)?;
    for (alias, traced) in aliases(iters.saturating_sub(1)) {
        if let Some(t) = trace.get(&traced).cloned() {
            trace.insert(alias.to_string(), t);
        }
    }

    let mut lines = Vec::new();
    let mut unmatched = Vec::new();
    let mut final_flow_error = f32::NAN;
    for (key, (shape, expected)) in &refs {
        if key.starts_with("input.") {
            continue;
        }
        let Some(actual) = trace.get(key) else {
            unmatched.push(key.clone());
            continue;
        };
        let dims = actual.dims().to_vec();
        let actual = to_vec(actual.clone());
        if dims != *shape {
            return Err(Error::Shape(format!("{key}: produced {dims:?}, reference {shape:?}")));
        }
        let max_abs_error = actual.iter().zip(expected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let scale = expected.iter().map(|v| v.abs()).fold(0.0f32, f32::max).max(1e-6);
        let relative_error = max_abs_error / scale;
        let is_flow = key.contains("flow");
        let passed = if is_flow { max_abs_error <= FLOW_TOLERANCE } else { relative_error <= FEATURE_TOLERANCE };
        if key == &format!("iter.{}.flow_up", iters.saturating_sub(1)) {
            final_flow_error = max_abs_error;
        }
        lines.push(VerifyLine {
            key: key.clone(),
            shape: shape.clone(),
            max_abs_error,
            relative_error,
            passed: passed && max_abs_error.is_finite(),
        });
    }
    Ok(VerifyReport { lines, final_flow_error, unmatched, configuration: config.to_string() })
}
