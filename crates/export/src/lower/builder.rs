//! The ONNX graph under construction: names, initializers, nodes and their attributes, written
//! with the ONNX protobuf types of `onnx-ir`, as burn-onnx's exporter writes them.

use std::collections::HashMap;

use burn::backend::DType;
use burn::backend::ir::{ScalarIr, TensorId, TensorIr};
use dgstereo_core::{Error, Result};
use onnx_ir::{GraphProto, TensorProto, TypeProto, ValueInfoProto};
use protobuf::{EnumOrUnknown, MessageField};

/// Builds the ONNX graph: names, initializers and nodes.
pub(crate) struct Lowering {
    proto: GraphProto,
    names: HashMap<TensorId, String>,
}

impl Lowering {
    /// An empty graph called `name` whose tensors `names` names (others are `t<id>`).
    pub(crate) fn new(name: &str, names: HashMap<TensorId, String>) -> Self {
        let mut proto = GraphProto::new();
        proto.name = name.into();
        Self { proto, names }
    }

    /// The graph, finished.
    pub(crate) fn finish(self) -> GraphProto {
        self.proto
    }

    /// Declares a runtime input.
    pub(crate) fn input(&mut self, name: String, tensor: &TensorIr) -> Result<()> {
        self.proto.input.push(value_info(name, tensor)?);
        Ok(())
    }

    /// Declares an output.
    pub(crate) fn output(&mut self, name: String, tensor: &TensorIr) -> Result<()> {
        self.proto.output.push(value_info(name, tensor)?);
        Ok(())
    }

    /// Adds a captured value as an initializer.
    pub(crate) fn initializer(&mut self, t: TensorProto) {
        self.proto.initializer.push(t);
    }

    /// The name of tensor `id` in the file.
    pub(crate) fn name(&self, id: TensorId) -> String {
        self.names.get(&id).cloned().unwrap_or_else(|| format!("t{}", id.value()))
    }

    /// Appends a node; `attributes` are added to it.
    pub(crate) fn node(&mut self, name: String, op_type: &str, inputs: Vec<String>, outputs: Vec<String>) -> &mut Self {
        let mut node = onnx_ir::NodeProto::new();
        node.name = name;
        node.op_type = op_type.into();
        node.input = inputs;
        node.output = outputs;
        self.proto.node.push(node);
        self
    }

    fn attribute(&mut self, name: &str, kind: i32) -> &mut onnx_ir::AttributeProto {
        let node = self.proto.node.last_mut().expect("an attribute follows its node");
        node.attribute.push(Default::default());
        let attribute = node.attribute.last_mut().expect("just pushed");
        attribute.name = name.into();
        attribute.type_ = EnumOrUnknown::from_i32(kind);
        attribute
    }

    /// An integer attribute of the last node.
    pub(crate) fn int(&mut self, name: &str, value: i64) -> &mut Self {
        self.attribute(name, 2).i = value;
        self
    }

    /// An integer-list attribute of the last node.
    pub(crate) fn ints(&mut self, name: &str, values: impl IntoIterator<Item = usize>) -> &mut Self {
        self.attribute(name, 7).ints = values.into_iter().map(|v| v as i64).collect();
        self
    }

    /// A float attribute of the last node.
    pub(crate) fn float(&mut self, name: &str, value: f32) -> &mut Self {
        self.attribute(name, 1).f = value;
        self
    }

    /// A string attribute of the last node.
    pub(crate) fn string(&mut self, name: &str, value: &'static str) -> &mut Self {
        self.attribute(name, 3).s = bytes::Bytes::from_static(value.as_bytes());
        self
    }

    /// A tensor attribute of the last node.
    pub(crate) fn tensor(&mut self, name: &str, value: TensorProto) -> &mut Self {
        self.attribute(name, 4).t = MessageField::some(value);
        self
    }

    /// Adds a one-dimensional `INT64` initializer.
    pub(crate) fn i64s(&mut self, name: String, values: &[i64]) -> String {
        let mut t = TensorProto::new();
        t.name = name.clone();
        t.data_type = 7;
        t.dims = vec![values.len() as i64];
        t.raw_data = bytes::Bytes::from(values.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<_>>());
        self.proto.initializer.push(t);
        name
    }

    /// Adds a one-element initializer holding `value` as `dtype`.
    pub(crate) fn scalar(&mut self, name: String, dtype: DType, value: ScalarIr) -> Result<String> {
        let mut t = scalar_tensor(dtype, value)?;
        t.name = name.clone();
        self.proto.initializer.push(t);
        Ok(name)
    }

    /// Adds an initializer of `dims` holding `data` (float32).
    pub(crate) fn f32s(&mut self, name: String, dims: &[usize], data: &[f32]) -> String {
        let mut t = TensorProto::new();
        t.name = name.clone();
        t.data_type = 1;
        t.dims = dims.iter().map(|&d| d as i64).collect();
        t.raw_data = bytes::Bytes::from(data.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<_>>());
        self.proto.initializer.push(t);
        name
    }
}

/// The ONNX type number of `dtype` (`TensorProto.DataType`).
pub(crate) fn onnx_dtype(dtype: DType) -> Result<i32> {
    Ok(match dtype {
        DType::F32 => 1,
        DType::U8 => 2,
        DType::I8 => 3,
        DType::U16 => 4,
        DType::I16 => 5,
        DType::I32 => 6,
        DType::I64 => 7,
        DType::Bool(_) => 9,
        DType::F16 => 10,
        DType::F64 => 11,
        DType::U32 => 12,
        DType::U64 => 13,
        DType::BF16 => 16,
        other => return Err(Error::unsupported(format!("{other:?} tensors"), "ONNX has no element type for them")),
    })
}

/// A one-element tensor holding `value` as `dtype`.
pub(crate) fn scalar_tensor(dtype: DType, value: ScalarIr) -> Result<TensorProto> {
    let mut t = TensorProto::new();
    t.data_type = onnx_dtype(dtype)?;
    t.dims = vec![1];
    let bytes = match dtype {
        DType::F32 => value.elem::<f32>().to_le_bytes().to_vec(),
        DType::F64 => value.elem::<f64>().to_le_bytes().to_vec(),
        DType::I32 => value.elem::<i32>().to_le_bytes().to_vec(),
        DType::I64 => value.elem::<i64>().to_le_bytes().to_vec(),
        DType::U8 => vec![value.elem::<u8>()],
        DType::Bool(_) => vec![value.elem::<bool>() as u8],
        other => return Err(Error::unsupported(format!("{other:?} scalars"), "ONNX has no scalar of that type")),
    };
    t.raw_data = bytes::Bytes::from(bytes);
    Ok(t)
}

fn value_info(name: String, tensor: &TensorIr) -> Result<ValueInfoProto> {
    let mut info = ValueInfoProto::new();
    info.name = name;
    let mut ty = TypeProto::new();
    let tensor_type = ty.mut_tensor_type();
    tensor_type.elem_type = onnx_dtype(tensor.dtype)?;
    let shape = tensor_type.shape.mut_or_insert_default();
    for &dim in tensor.shape.iter() {
        shape.dim.push(Default::default());
        shape.dim.last_mut().expect("just pushed").set_dim_value(dim as i64);
    }
    info.type_ = MessageField::some(ty);
    Ok(info)
}
