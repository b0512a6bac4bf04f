//! The lowering table: one ONNX node pattern per burn-ir operation the stereo models use. Where
//! burn-onnx's exporter covers an operation, the nodes are the ones it writes.

use burn::backend::DType;
use burn::backend::ir::{
    ActivationOperationIr, BaseOperationIr, BoolOperationIr, FloatOperationIr, IntOperationIr, InterpolateModeIr,
    ModuleOperationIr, NumericOperationIr, OperationIr, PadModeIr, ScalarIr,
};
use dgstereo_core::{Error, Result};

use super::builder::{Lowering, onnx_dtype, scalar_tensor};
use super::{transformer, volume};

/// The burn-ir operations the table lowers, as their IR names them (for errors and docs).
pub const LOWERED: &[&str] = &[
    "Relu",
    "Sigmoid",
    "Tanh",
    "Softmax",
    "Sqrt",
    "Exp",
    "Log",
    "Floor",
    "Neg",
    "Abs",
    "Matmul",
    "Add",
    "Sub",
    "Mul",
    "Div",
    "AddScalar",
    "SubScalar",
    "MulScalar",
    "DivScalar",
    "Clamp",
    "GreaterEqualElem",
    "LowerEqualElem",
    "GreaterElem",
    "LowerElem",
    "ClampMin",
    "ClampMax",
    "MeanDim",
    "SumDim",
    "MinDim",
    "MaxDim",
    "Cat",
    "Reshape",
    "Expand",
    "Permute",
    "SwapDims",
    "Slice",
    "Gather",
    "Zeros",
    "Ones",
    "Full",
    "Pad",
    "IntoFloat",
    "IntoInt",
    "Conv2d",
    "AvgPool2d",
    "MaxPool2d",
    "Interpolate",
    "Unfold4d",
    "DeformableConv2d",
    "Gelu",
    "Linear",
    "LayerNorm",
    "Attention",
    "ConvTranspose2d",
    "LeakyRelu",
    "Conv3d",
    "ConvTranspose3d",
    "SliceAssign",
    "And",
    "Or",
    "Xor",
    "Not",
    "MaskWhere",
    "MaskFill",
];

fn unsupported(index: usize, operation: &OperationIr) -> Error {
    let text = format!("{operation:?}");
    let kind = text.split('{').next().unwrap_or_default().trim_end_matches(['(', ' ']);
    let shapes: Vec<String> = operation.inputs().map(|t| format!("{:?}", t.shape.as_slice())).collect();
    Error::unsupported(
        format!("ONNX export of operation {index} ({kind}, inputs {})", shapes.join(", ")),
        format!("it has no lowering; the table covers {}", LOWERED.join(", ")),
    )
}

fn names(l: &Lowering, operation: &OperationIr) -> (Vec<String>, Vec<String>) {
    (operation.inputs().map(|t| l.name(t.id)).collect(), operation.outputs().map(|t| l.name(t.id)).collect())
}

/// Appends the nodes of `operation` (operation `index` of the graph).
pub(super) fn lower(l: &mut Lowering, index: usize, operation: &OperationIr) -> Result<()> {
    let node = format!("n{index}");
    // Operations whose ONNX node has the same tensor inputs and outputs.
    let direct = match operation {
        OperationIr::Activation(ActivationOperationIr::Relu(_)) => Some("Relu"),
        OperationIr::Activation(ActivationOperationIr::Sigmoid(_)) => Some("Sigmoid"),
        OperationIr::Bool(BoolOperationIr::And(_)) => Some("And"),
        OperationIr::Bool(BoolOperationIr::Or(_)) => Some("Or"),
        OperationIr::Bool(BoolOperationIr::Xor(_)) => Some("Xor"),
        OperationIr::Bool(BoolOperationIr::Not(_)) => Some("Not"),
        OperationIr::Float(_, op) => match op {
            FloatOperationIr::Exp(_) => Some("Exp"),
            FloatOperationIr::Log(_) => Some("Log"),
            FloatOperationIr::Sqrt(_) => Some("Sqrt"),
            FloatOperationIr::Tanh(_) => Some("Tanh"),
            FloatOperationIr::Floor(_) => Some("Floor"),
            FloatOperationIr::Matmul(_) => Some("MatMul"),
            _ => None,
        },
        OperationIr::NumericFloat(_, op) | OperationIr::NumericInt(_, op) => match op {
            NumericOperationIr::Add(_) => Some("Add"),
            NumericOperationIr::Sub(_) => Some("Sub"),
            NumericOperationIr::Mul(_) => Some("Mul"),
            NumericOperationIr::Div(_) => Some("Div"),
            NumericOperationIr::Neg(_) => Some("Neg"),
            NumericOperationIr::Abs(_) => Some("Abs"),
            _ => None,
        },
        _ => None,
    };
    if let Some(op_type) = direct {
        let (inputs, outputs) = names(l, operation);
        l.node(node, op_type, inputs, outputs);
        return Ok(());
    }
    match operation {
        // Values and drops carry no computation: the values are the file's initializers.
        OperationIr::Init(_) | OperationIr::Drop(_) => {}
        OperationIr::Activation(ActivationOperationIr::Gelu(op)) => transformer::gelu(l, index, op)?,
        OperationIr::Activation(ActivationOperationIr::LeakyRelu(op)) => volume::leaky_relu(l, index, op)?,
        OperationIr::Activation(ActivationOperationIr::Softmax(op)) => {
            l.node(node, "Softmax", vec![l.name(op.input.id)], vec![l.name(op.out.id)]).int("axis", op.axis as i64);
        }
        OperationIr::Float(_, FloatOperationIr::IntoInt(op))
        | OperationIr::Int(IntOperationIr::IntoFloat(op))
        | OperationIr::Bool(BoolOperationIr::IntoFloat(op) | BoolOperationIr::IntoInt(op)) => {
            let to = onnx_dtype(op.out.dtype)? as i64;
            l.node(node, "Cast", vec![l.name(op.input.id)], vec![l.name(op.out.id)]).int("to", to);
        }
        OperationIr::NumericFloat(_, op) | OperationIr::NumericInt(_, op) => lower_numeric(l, index, operation, op)?,
        OperationIr::BaseFloat(op) | OperationIr::BaseInt(op) | OperationIr::BaseBool(op) => {
            lower_base(l, index, operation, op)?
        }
        OperationIr::Module(op) => lower_module(l, index, operation, op)?,
        _ => return Err(unsupported(index, operation)),
    }
    Ok(())
}

fn lower_numeric(l: &mut Lowering, index: usize, operation: &OperationIr, op: &NumericOperationIr) -> Result<()> {
    let node = format!("n{index}");
    let scalar_op = match op {
        NumericOperationIr::AddScalar(s) => Some(("Add", s)),
        NumericOperationIr::SubScalar(s) => Some(("Sub", s)),
        NumericOperationIr::MulScalar(s) => Some(("Mul", s)),
        NumericOperationIr::DivScalar(s) => Some(("Div", s)),
        NumericOperationIr::GreaterEqualElem(s) => Some(("GreaterOrEqual", s)),
        NumericOperationIr::LowerEqualElem(s) => Some(("LessOrEqual", s)),
        NumericOperationIr::GreaterElem(s) => Some(("Greater", s)),
        NumericOperationIr::LowerElem(s) => Some(("Less", s)),
        NumericOperationIr::ClampMin(s) => Some(("Max", s)),
        NumericOperationIr::ClampMax(s) => Some(("Min", s)),
        _ => None,
    };
    if let Some((op_type, s)) = scalar_op {
        let rhs = l.scalar(format!("n{index}_scalar"), s.lhs.dtype, s.rhs)?;
        l.node(node, op_type, vec![l.name(s.lhs.id), rhs], vec![l.name(s.out.id)]);
        return Ok(());
    }
    match op {
        NumericOperationIr::Clamp(c) => {
            let min = l.scalar(format!("n{index}_min"), c.tensor.dtype, c.min)?;
            let max = l.scalar(format!("n{index}_max"), c.tensor.dtype, c.max)?;
            // Clip takes scalars (rank 0); reshape the one-element initializers.
            let empty = l.i64s(format!("n{index}_scalar_shape"), &[]);
            let (min0, max0) = (format!("n{index}_min0"), format!("n{index}_max0"));
            l.node(format!("n{index}_min_shape"), "Reshape", vec![min, empty.clone()], vec![min0.clone()]);
            l.node(format!("n{index}_max_shape"), "Reshape", vec![max, empty], vec![max0.clone()]);
            l.node(node, "Clip", vec![l.name(c.tensor.id), min0, max0], vec![l.name(c.out.id)]);
        }
        NumericOperationIr::MeanDim(r)
        | NumericOperationIr::SumDim(r)
        | NumericOperationIr::MinDim(r)
        | NumericOperationIr::MaxDim(r) => {
            let op_type = match op {
                NumericOperationIr::MeanDim(_) => "ReduceMean",
                NumericOperationIr::SumDim(_) => "ReduceSum",
                NumericOperationIr::MinDim(_) => "ReduceMin",
                _ => "ReduceMax",
            };
            let axes = l.i64s(format!("n{index}_axes"), &[r.axis as i64]);
            let keep = r.out.shape.num_dims() == r.input.shape.num_dims();
            l.node(node, op_type, vec![l.name(r.input.id), axes], vec![l.name(r.out.id)]).int("keepdims", keep as i64);
        }
        NumericOperationIr::Full(f) => {
            let shape = l.i64s(format!("n{index}_shape"), &dims(&f.out.shape));
            let value = scalar_tensor(f.out.dtype, f.value)?;
            l.node(node, "ConstantOfShape", vec![shape], vec![l.name(f.out.id)]).tensor("value", value);
        }
        NumericOperationIr::Pad(p) => {
            let pads: Vec<i64> =
                p.padding.iter().map(|(b, _)| *b as i64).chain(p.padding.iter().map(|(_, a)| *a as i64)).collect();
            let pads = l.i64s(format!("n{index}_pads"), &pads);
            let mut inputs = vec![l.name(p.input.id), pads];
            let mode = match p.mode {
                PadModeIr::Constant(value) => {
                    inputs.push(l.scalar(format!("n{index}_value"), p.input.dtype, value)?);
                    "constant"
                }
                PadModeIr::Reflect => "reflect",
                PadModeIr::Edge => "edge",
            };
            l.node(node, "Pad", inputs, vec![l.name(p.out.id)]).string("mode", mode);
        }
        _ => return Err(unsupported(index, operation)),
    }
    Ok(())
}

fn dims(shape: &burn::backend::Shape) -> Vec<i64> {
    shape.iter().map(|&d| d as i64).collect()
}

fn lower_base(l: &mut Lowering, index: usize, operation: &OperationIr, op: &BaseOperationIr) -> Result<()> {
    let node = format!("n{index}");
    match op {
        BaseOperationIr::Reshape(r) => {
            let shape = l.i64s(format!("n{index}_shape"), &dims(&r.out.shape));
            l.node(node, "Reshape", vec![l.name(r.input.id), shape], vec![l.name(r.out.id)]);
        }
        BaseOperationIr::Expand(r) => {
            let shape = l.i64s(format!("n{index}_shape"), &dims(&r.out.shape));
            l.node(node, "Expand", vec![l.name(r.input.id), shape], vec![l.name(r.out.id)]);
        }
        BaseOperationIr::Permute(p) => {
            l.node(node, "Transpose", vec![l.name(p.input.id)], vec![l.name(p.out.id)]).ints("perm", p.axes.clone());
        }
        BaseOperationIr::SwapDims(s) => {
            let mut perm: Vec<usize> = (0..s.input.shape.num_dims()).collect();
            perm.swap(s.dim1, s.dim2);
            l.node(node, "Transpose", vec![l.name(s.input.id)], vec![l.name(s.out.id)]).ints("perm", perm);
        }
        BaseOperationIr::Cat(c) => {
            let inputs = c.tensors.iter().map(|t| l.name(t.id)).collect();
            l.node(node, "Concat", inputs, vec![l.name(c.out.id)]).int("axis", c.dim as i64);
        }
        BaseOperationIr::SliceAssign(s) => volume::slice_assign(l, index, s)?,
        // burn's mask_where takes `value` where the mask holds; ONNX's Where its second input.
        BaseOperationIr::MaskWhere(m) => {
            let inputs = vec![l.name(m.mask.id), l.name(m.value.id), l.name(m.tensor.id)];
            l.node(node, "Where", inputs, vec![l.name(m.out.id)]);
        }
        BaseOperationIr::MaskFill(m) => {
            let value = l.scalar(format!("n{index}_value"), m.tensor.dtype, m.value)?;
            l.node(node, "Where", vec![l.name(m.mask.id), value, l.name(m.tensor.id)], vec![l.name(m.out.id)]);
        }
        BaseOperationIr::Slice(s) => {
            let (starts, ends): (Vec<i64>, Vec<i64>) =
                s.ranges.iter().map(|r| slice_bounds(r.start, r.end, r.step)).unzip();
            let axes: Vec<i64> = (0..s.ranges.len() as i64).collect();
            let steps: Vec<i64> = s.ranges.iter().map(|r| r.step as i64).collect();
            let inputs = vec![
                l.name(s.tensor.id),
                l.i64s(format!("n{index}_starts"), &starts),
                l.i64s(format!("n{index}_ends"), &ends),
                l.i64s(format!("n{index}_axes"), &axes),
                l.i64s(format!("n{index}_steps"), &steps),
            ];
            l.node(node, "Slice", inputs, vec![l.name(s.out.id)]);
        }
        BaseOperationIr::Gather(g) => {
            // burn's gather is torch.gather: ONNX's GatherElements.
            let indices = int64(l, index, &g.indices)?;
            l.node(node, "GatherElements", vec![l.name(g.tensor.id), indices], vec![l.name(g.out.id)])
                .int("axis", g.dim as i64);
        }
        BaseOperationIr::Zeros(c) | BaseOperationIr::Ones(c) => {
            let one = matches!(op, BaseOperationIr::Ones(_));
            let shape = l.i64s(format!("n{index}_shape"), &dims(&c.out.shape));
            let value = scalar_tensor(c.out.dtype, ScalarIr::new(one as i64, &c.out.dtype))?;
            l.node(node, "ConstantOfShape", vec![shape], vec![l.name(c.out.id)]).tensor("value", value);
        }
        _ => return Err(unsupported(index, operation)),
    }
    Ok(())
}

/// `indices` as `INT64` (a `Cast` where they are another integer type).
fn int64(l: &mut Lowering, index: usize, indices: &burn::backend::ir::TensorIr) -> Result<String> {
    if indices.dtype == DType::I64 {
        return Ok(l.name(indices.id));
    }
    let out = format!("n{index}_indices64");
    l.node(out.clone(), "Cast", vec![l.name(indices.id)], vec![out.clone()]).int("to", 7);
    Ok(out)
}

/// ONNX bounds of a range as burn's slice records it (clamped, ascending; a negative step walks
/// it backwards), as burn-onnx converts them.
fn slice_bounds(start: isize, end: Option<isize>, step: isize) -> (i64, i64) {
    if step > 0 {
        return (start as i64, end.map_or(i64::MAX, |e| e as i64));
    }
    if end.is_some_and(|e| start >= e) {
        return (0, 0);
    }
    let onnx_start = end.map_or(-1, |e| e.saturating_sub(1) as i64);
    let onnx_end = if start == 0 { i64::MIN } else { start.saturating_sub(1) as i64 };
    (onnx_start, onnx_end)
}

/// ONNX's `pads` (begins, then ends) of a padding that is the same at both ends of each axis.
fn symmetric(padding: [usize; 2]) -> [usize; 4] {
    [padding[0], padding[1], padding[0], padding[1]]
}

fn lower_module(l: &mut Lowering, index: usize, operation: &OperationIr, op: &ModuleOperationIr) -> Result<()> {
    let node = format!("n{index}");
    match op {
        ModuleOperationIr::Conv2d(c) => {
            let mut inputs = vec![l.name(c.x.id), l.name(c.weight.id)];
            if let Some(bias) = &c.bias {
                inputs.push(l.name(bias.id));
            }
            let p = c.options.padding;
            l.node(node, "Conv", inputs, vec![l.name(c.out.id)])
                .ints("strides", c.options.stride)
                .ints("dilations", c.options.dilation)
                .ints("pads", [p[0].0, p[1].0, p[0].1, p[1].1])
                .int("group", c.options.groups as i64);
        }
        ModuleOperationIr::AvgPool2d(p) => {
            l.node(node, "AveragePool", vec![l.name(p.x.id)], vec![l.name(p.out.id)])
                .ints("kernel_shape", p.kernel_size)
                .ints("strides", p.stride)
                .ints("pads", symmetric(p.padding))
                .int("ceil_mode", p.ceil_mode as i64)
                .int("count_include_pad", p.count_include_pad as i64);
        }
        ModuleOperationIr::MaxPool2d(p) => {
            l.node(node, "MaxPool", vec![l.name(p.x.id)], vec![l.name(p.out.id)])
                .ints("kernel_shape", p.kernel_size)
                .ints("strides", p.stride)
                .ints("dilations", p.dilation)
                .ints("pads", symmetric(p.padding))
                .int("ceil_mode", p.ceil_mode as i64);
        }
        ModuleOperationIr::Interpolate(i) => {
            let (mode, coordinates, nearest) = match i.options.mode {
                InterpolateModeIr::Nearest => ("nearest", "asymmetric", Some("floor")),
                InterpolateModeIr::Bilinear => {
                    ("linear", if i.options.align_corners { "align_corners" } else { "half_pixel" }, None)
                }
                InterpolateModeIr::Bicubic => {
                    ("cubic", if i.options.align_corners { "align_corners" } else { "half_pixel" }, None)
                }
                _ => return Err(unsupported(index, operation)),
            };
            let sizes = l.i64s(format!("n{index}_sizes"), &i.output_size.map(|d| d as i64));
            let n = l.node(
                node,
                "Resize",
                vec![l.name(i.x.id), String::new(), String::new(), sizes],
                vec![l.name(i.out.id)],
            );
            n.ints("axes", [2, 3]).string("mode", mode).string("coordinate_transformation_mode", coordinates);
            if let Some(nearest) = nearest {
                n.string("nearest_mode", nearest);
            }
            if matches!(i.options.mode, InterpolateModeIr::Bicubic) {
                n.float("cubic_coeff_a", -0.75);
            }
        }
        ModuleOperationIr::DeformableConv2d(d) => {
            // ONNX's DeformConv (opset 19) has torchvision's offset layout, as burn's operation.
            let [_, _, kh, kw] = [d.weight.shape[0], d.weight.shape[1], d.weight.shape[2], d.weight.shape[3]];
            let mut inputs = vec![l.name(d.x.id), l.name(d.weight.id), l.name(d.offset.id)];
            inputs.push(d.bias.as_ref().map(|b| l.name(b.id)).unwrap_or_default());
            if let Some(mask) = &d.mask {
                inputs.push(l.name(mask.id));
            }
            let o = &d.options;
            l.node(node, "DeformConv", inputs, vec![l.name(d.out.id)])
                .ints("kernel_shape", [kh, kw])
                .ints("strides", o.stride)
                .ints("dilations", o.dilation)
                .ints("pads", symmetric(o.padding))
                .int("group", o.weight_groups as i64)
                .int("offset_group", o.offset_groups as i64);
        }
        ModuleOperationIr::Unfold4d(u) => {
            // ONNX has no unfold: a grouped convolution whose kernels pick one tap each (one-hot,
            // exact) gives the patches as channels, `c * kh * kw + i * kw + j`, then a reshape.
            let c = u.x.shape[1];
            let [kh, kw] = u.kernel_size;
            let taps = kh * kw;
            let mut weight = vec![0f32; c * taps * taps];
            for ch in 0..c {
                for t in 0..taps {
                    weight[(ch * taps + t) * taps + t] = 1.0;
                }
            }
            let weight = l.f32s(format!("n{index}_taps"), &[c * taps, 1, kh, kw], &weight);
            let patches = format!("n{index}_patches");
            let o = &u.options;
            l.node(format!("n{index}_conv"), "Conv", vec![l.name(u.x.id), weight], vec![patches.clone()])
                .ints("strides", o.stride)
                .ints("dilations", o.dilation)
                .ints("pads", symmetric(o.padding))
                .int("group", c as i64);
            let shape = l.i64s(format!("n{index}_shape"), &dims(&u.out.shape));
            l.node(node, "Reshape", vec![patches, shape], vec![l.name(u.out.id)]);
        }
        ModuleOperationIr::Linear(op) => transformer::linear(l, index, op)?,
        ModuleOperationIr::LayerNorm(op) => transformer::layer_norm(l, index, op)?,
        ModuleOperationIr::Attention(op) => transformer::attention(l, index, op)?,
        ModuleOperationIr::ConvTranspose2d(op) => transformer::conv_transpose2d(l, index, op)?,
        ModuleOperationIr::Conv3d(op) => volume::conv3d(l, index, op)?,
        ModuleOperationIr::ConvTranspose3d(op) => volume::conv_transpose3d(l, index, op)?,
        _ => return Err(unsupported(index, operation)),
    }
    Ok(())
}
