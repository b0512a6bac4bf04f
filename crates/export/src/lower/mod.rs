//! Lowering a captured burn-ir graph to an ONNX model: the graph's boundaries and values first,
//! then one ONNX node pattern per burn-ir operation (`lower/table.rs`, and `lower/transformer.rs`
//! for a monocular network's ViT and DPT head, `lower/volume.rs` for a 3D cost-volume network's
//! convolutions; [`LOWERED`] lists them).
//! An operation the table lacks is an error naming it, never a file.
//!
//! The model is static: every shape is the captured one (reshape targets, expand shapes and
//! created tensors take their sizes from the capture), as TensorRT's static engines want.

mod builder;
mod table;
mod transformer;
mod volume;

use std::collections::{BTreeMap, HashMap, HashSet};

use builder::{Lowering, onnx_dtype};
use burn::backend::ir::{OperationIr, TensorId, TensorIr};
use burn::tensor::TensorData;
use dgstereo_core::{Error, Result};
use onnx_ir::{ModelProto, TensorProto};
use protobuf::{Message, MessageField};

pub use table::LOWERED;

/// The operator set the files declare (ONNX 1.14): `ReduceMean` and `ReduceSum` take their
/// axes as an input, and `DeformConv` exists.
pub const OPSET: i64 = 19;

/// The ONNX IR version the files declare (the lowest that opset 19 allows).
const IR_VERSION: i64 = 9;

/// A captured graph's boundaries, by the names the ONNX file gives them.
#[derive(Debug, Clone)]
pub struct Boundaries {
    /// `(tensor, name)` of each runtime input, in order.
    pub inputs: Vec<(TensorId, String)>,
    /// `(tensor, name)` of each output, in order.
    pub outputs: Vec<(TensorId, String)>,
}

/// The operations the outputs depend on (what a probe recorded on the side is left out).
fn needed(operations: &[OperationIr], outputs: &[TensorId]) -> Vec<bool> {
    let mut wanted: HashSet<TensorId> = outputs.iter().copied().collect();
    let mut keep = vec![false; operations.len()];
    for (i, op) in operations.iter().enumerate().rev() {
        if matches!(op, OperationIr::Init(_) | OperationIr::Drop(_)) {
            continue;
        }
        if op.outputs().any(|t| wanted.contains(&t.id)) {
            keep[i] = true;
            wanted.extend(op.inputs().map(|t| t.id));
        }
    }
    keep
}

/// Where operation `index` stands in the forward pass: after the last of `landmarks` (named
/// activations) that an earlier operation made.
pub fn place(operations: &[OperationIr], landmarks: &[(TensorId, String)], index: usize) -> String {
    let names: HashMap<TensorId, &str> = landmarks.iter().map(|(id, n)| (*id, n.as_str())).collect();
    let last = operations[..index.min(operations.len())]
        .iter()
        .rev()
        .filter(|op| !matches!(op, OperationIr::Init(_) | OperationIr::Drop(_)))
        .find_map(|op| op.outputs().find_map(|t| names.get(&t.id)));
    match last {
        Some(name) => format!("after `{name}`"),
        None => "before `fnet.left` (in the fusion or the encoders)".to_string(),
    }
}

/// The ONNX model of `operations` with `values` (the captured constants and weights) embedded
/// and the runtime inputs and outputs named by `boundaries`; only the operations the outputs
/// depend on are written. `landmarks` (named activations) place an operation the table lacks
/// in the error.
pub fn lower_graph(
    operations: &[OperationIr],
    values: &BTreeMap<TensorId, TensorData>,
    boundaries: &Boundaries,
    landmarks: &[(TensorId, String)],
    producer: &str,
) -> Result<ModelProto> {
    let mut names = HashMap::new();
    for (id, name) in boundaries.inputs.iter().chain(&boundaries.outputs) {
        names.insert(*id, name.clone());
    }
    let tensors: HashMap<TensorId, &TensorIr> =
        operations.iter().flat_map(OperationIr::nodes).map(|t| (t.id, t)).collect();
    let mut lowering = Lowering::new(producer, names);
    for (id, name) in &boundaries.inputs {
        let t = tensors.get(id).ok_or_else(|| Error::Internal(format!("input {name} is used by no operation")))?;
        lowering.input(name.clone(), t)?;
    }
    for (id, name) in &boundaries.outputs {
        let t = tensors.get(id).ok_or_else(|| Error::Internal(format!("output {name} is made by no operation")))?;
        lowering.output(name.clone(), t)?;
    }
    let runtime: HashSet<TensorId> = boundaries.inputs.iter().map(|(id, _)| *id).collect();
    let outputs: Vec<TensorId> = boundaries.outputs.iter().map(|(id, _)| *id).collect();
    let keep = needed(operations, &outputs);
    // Only the values a kept operation reads (a shared backbone leaves some weights unread).
    let read: HashSet<TensorId> =
        operations.iter().zip(&keep).filter(|(_, k)| **k).flat_map(|(op, _)| op.inputs()).map(|t| t.id).collect();
    for (id, data) in values.iter().filter(|(id, _)| !runtime.contains(id) && read.contains(id)) {
        let mut t = TensorProto::new();
        t.name = lowering.name(*id);
        t.data_type = onnx_dtype(data.dtype())?;
        t.dims = data.shape().iter().map(|&d| d as i64).collect();
        t.raw_data = bytes::Bytes::copy_from_slice(data.as_bytes());
        lowering.initializer(t);
    }
    for (index, operation) in operations.iter().enumerate().filter(|(i, _)| keep[*i]) {
        table::lower(&mut lowering, index, operation)
            .map_err(|e| e.context(format!("the operation {}", place(operations, landmarks, index))))?;
    }
    let mut model = ModelProto::new();
    model.ir_version = IR_VERSION;
    model.producer_name = producer.into();
    model.graph = MessageField::some(lowering.finish());
    model.opset_import.push(Default::default());
    model.opset_import[0].version = OPSET;
    Ok(model)
}

/// The bytes of `model`, as an `.onnx` file holds them.
pub fn to_bytes(model: &ModelProto) -> Result<Vec<u8>> {
    model.write_to_bytes().map_err(|e| Error::encode("the ONNX model", e))
}
