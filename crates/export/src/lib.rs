//! ONNX export of a loaded stereo model: `dgstereo export onnx`, `Model.export_onnx`.
//!
//! Design decision: the forward pass is not written again for ONNX. burn's capture device runs
//! the model's own inference code ([`capture`]), on which the kernels' dispatch takes burn's
//! stock operations, and records it as a burn-ir graph with the weights; [`lower`] then writes
//! one ONNX node pattern per burn-ir operation, against the ONNX protobuf types of burn's
//! `onnx-ir`. A new layer that uses only lowered operations exports without a change here; an
//! operation the table lacks is an error naming it.

#![deny(missing_docs)]

pub mod capture;
pub mod lower;

use dgstereo_core::{Error, Result};
use dgstereo_model::StereoModel;

pub use lower::OPSET;

/// The smallest side of a pair the file may take: the smallest `infer` accepts
/// (`dgstereo_inference::working_size::MIN_WORKING_SIZE`, which a test compares with this).
pub const MIN_SIDE: usize = 32;

/// An exported model: the file's bytes and what a user needs to run it.
#[derive(Debug, Clone)]
pub struct OnnxExport {
    /// The `.onnx` file.
    pub bytes: Vec<u8>,
    /// `(name, shape)` of each input.
    pub inputs: Vec<(String, Vec<usize>)>,
    /// `(name, shape)` of each output.
    pub outputs: Vec<(String, Vec<usize>)>,
    /// The number of nodes.
    pub nodes: usize,
}

impl OnnxExport {
    /// Writes the file to `path` whole or not at all: a temporary file beside it, then renamed
    /// over it ([`dgstereo_core::atomic_file::commit_file`]).
    ///
    /// # Errors
    /// A file that cannot be written ([`Error::Io`], naming it).
    pub fn write(&self, path: &std::path::Path) -> Result<()> {
        let tmp = path.with_extension("onnx.tmp");
        std::fs::write(&tmp, &self.bytes).map_err(|e| Error::io(&tmp, e))?;
        dgstereo_core::atomic_file::commit_file(&tmp, path)
    }
}

/// The ONNX model of `model` for pairs of `height x width` (RGB 0..255), `iters` update
/// iterations unrolled: inputs `left`, `right` (`1x3xHxW`, and `left_prior`, `right_prior`
/// `1x1xHxW` for a model with a depth prior), output `disparity` (`1x1xHxW`, positive; the
/// padding to the network's multiple and the crop back are inside the graph).
pub fn export_onnx(model: &StereoModel, height: usize, width: usize, iters: usize) -> Result<OnnxExport> {
    if height < MIN_SIDE || width < MIN_SIDE {
        return Err(Error::config(
            "size",
            format!("{height}x{width}: the network needs at least {MIN_SIDE} pixels on each side, as `infer` does"),
        ));
    }
    if iters == 0 {
        return Err(Error::config("iters", "must be at least 1"));
    }
    let captured = capture::capture_disparity(model, height, width, iters)?;
    let proto = lower::lower_graph(
        &captured.graph.graph.operations,
        &captured.graph.values,
        &captured.boundaries,
        &captured.landmarks,
        "dgstereo",
    )?;
    let shape = |name: &str| {
        let input = proto.graph.input.iter().chain(&proto.graph.output).find(|v| v.name == name);
        input
            .and_then(|v| {
                v.type_.tensor_type().shape.as_ref().map(|s| s.dim.iter().map(|d| d.dim_value() as usize).collect())
            })
            .unwrap_or_default()
    };
    let inputs = captured.boundaries.inputs.iter().map(|(_, n)| (n.clone(), shape(n))).collect();
    let outputs = captured.boundaries.outputs.iter().map(|(_, n)| (n.clone(), shape(n))).collect();
    let nodes = proto.graph.node.len();
    Ok(OnnxExport { bytes: lower::to_bytes(&proto)?, inputs, outputs, nodes })
}
