//! The lowerings of the operations a 3D cost-volume network adds (IGEV-Stereo's geometry
//! encoding volume): 3D convolutions, transposed 3D convolutions, the LeakyReLU of its blocks and
//! the slice assignments that write its correlation volume.
//! ONNX's `Conv` and `ConvTranspose` take any number of spatial axes, with burn's and PyTorch's
//! weight layouts.

use burn::backend::ir::{Conv3dOpIr, ConvTranspose3dOpIr, ScalarOpIr, SliceAssignOpIr};
use dgstereo_core::{Error, Result};

use super::builder::Lowering;

/// `Conv3d`: ONNX's `Conv` over depth, height and width (weight `[out, in / groups, kd, kh, kw]`).
pub(super) fn conv3d(l: &mut Lowering, index: usize, op: &Conv3dOpIr) -> Result<()> {
    let mut inputs = vec![l.name(op.x.id), l.name(op.weight.id)];
    inputs.extend(op.bias.as_ref().map(|b| l.name(b.id)));
    let o = &op.options;
    let kernel = [op.weight.shape[2], op.weight.shape[3], op.weight.shape[4]];
    l.node(format!("n{index}"), "Conv", inputs, vec![l.name(op.out.id)])
        .ints("kernel_shape", kernel)
        .ints("strides", o.stride)
        .ints("dilations", o.dilation)
        .ints("pads", symmetric3(o.padding))
        .int("group", o.groups as i64);
    Ok(())
}

/// `ConvTranspose3d`: ONNX's `ConvTranspose` over depth, height and width (weight
/// `[in, out / groups, kd, kh, kw]`).
pub(super) fn conv_transpose3d(l: &mut Lowering, index: usize, op: &ConvTranspose3dOpIr) -> Result<()> {
    let mut inputs = vec![l.name(op.x.id), l.name(op.weight.id)];
    inputs.extend(op.bias.as_ref().map(|b| l.name(b.id)));
    let o = &op.options;
    let kernel = [op.weight.shape[2], op.weight.shape[3], op.weight.shape[4]];
    l.node(format!("n{index}"), "ConvTranspose", inputs, vec![l.name(op.out.id)])
        .ints("kernel_shape", kernel)
        .ints("strides", o.stride)
        .ints("dilations", o.dilation)
        .ints("pads", symmetric3(o.padding))
        .ints("output_padding", o.padding_out)
        .int("group", o.groups as i64);
    Ok(())
}

/// `LeakyRelu` with burn's negative slope: ONNX's `LeakyRelu`, its `alpha`.
pub(super) fn leaky_relu(l: &mut Lowering, index: usize, op: &ScalarOpIr) -> Result<()> {
    let alpha = op.rhs.elem::<f64>() as f32;
    l.node(format!("n{index}"), "LeakyRelu", vec![l.name(op.lhs.id)], vec![l.name(op.out.id)]).float("alpha", alpha);
    Ok(())
}

/// ONNX's `pads` (begins, then ends) of a padding that is the same at both ends of each of the
/// three axes.
fn symmetric3(padding: [usize; 3]) -> [usize; 6] {
    [padding[0], padding[1], padding[2], padding[0], padding[1], padding[2]]
}

/// `SliceAssign` with unit steps (a cost volume written disparity by disparity): ONNX's
/// `ScatterND` would need an index per written value, so the output is put together from `Slice`
/// and `Concat` instead. Along each axis the region does not span, from the last inwards, the
/// tensor's parts before and after the region are concatenated around what is built so far,
/// starting from the value.
pub(super) fn slice_assign(l: &mut Lowering, index: usize, op: &SliceAssignOpIr) -> Result<()> {
    let shape: Vec<usize> = op.tensor.shape.as_slice().to_vec();
    let mut bounds = Vec::with_capacity(shape.len());
    for (axis, &size) in shape.iter().enumerate() {
        let Some(range) = op.ranges.get(axis) else {
            bounds.push((0, size));
            continue;
        };
        if range.step != 1 {
            return Err(Error::unsupported(
                format!("ONNX export of operation {index} (SliceAssign with step {} on axis {axis})", range.step),
                "the lowering writes unit-step regions only",
            ));
        }
        let resolve = |i: isize| if i < 0 { (size as isize + i).max(0) as usize } else { (i as usize).min(size) };
        let start = resolve(range.start);
        bounds.push((start, range.end.map_or(size, resolve).max(start)));
    }
    let t = |s: String| format!("n{index}_{s}");
    let out = l.name(op.out.id);
    let partial: Vec<usize> = (0..shape.len()).filter(|&a| bounds[a] != (0, shape[a])).collect();
    let mut built = l.name(op.value.id);
    for (i, &axis) in partial.iter().enumerate().rev() {
        // The tensor within the region on the axes before `axis`, and `from..to` on `axis`.
        let part = |l: &mut Lowering, from: usize, to: usize, name: String| {
            let (starts, ends): (Vec<i64>, Vec<i64>) = (0..=axis)
                .map(|a| if a == axis { (from as i64, to as i64) } else { (bounds[a].0 as i64, bounds[a].1 as i64) })
                .unzip();
            let axes: Vec<i64> = (0..=axis as i64).collect();
            let inputs = vec![
                l.name(op.tensor.id),
                l.i64s(t(format!("{name}_starts")), &starts),
                l.i64s(t(format!("{name}_ends")), &ends),
                l.i64s(t(format!("{name}_axes")), &axes),
            ];
            l.node(t(format!("{name}_slice")), "Slice", inputs, vec![t(name.clone())]);
            t(name)
        };
        let (start, end) = bounds[axis];
        let mut pieces = Vec::new();
        if start > 0 {
            pieces.push(part(l, 0, start, format!("before{axis}")));
        }
        pieces.push(built);
        if end < shape[axis] {
            pieces.push(part(l, end, shape[axis], format!("after{axis}")));
        }
        built = if i == 0 { out.clone() } else { t(format!("axis{axis}")) };
        l.node(t(format!("concat{axis}")), "Concat", pieces, vec![built.clone()]).int("axis", axis as i64);
    }
    if partial.is_empty() {
        // The value covers the whole tensor.
        l.node(format!("n{index}"), "Identity", vec![built], vec![out]);
    }
    Ok(())
}
