//! The lowerings of the operations a 3D cost-volume network adds (IGEV-Stereo's geometry
//! encoding volume): 3D convolutions, transposed 3D convolutions and the LeakyReLU of its blocks.
//! ONNX's `Conv` and `ConvTranspose` take any number of spatial axes, with burn's and PyTorch's
//! weight layouts.

use burn::backend::ir::{Conv3dOpIr, ConvTranspose3dOpIr, ScalarOpIr};
use dgstereo_core::Result;

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
