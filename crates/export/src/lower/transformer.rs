//! The lowerings of the operations a monocular network inside the stereo network adds
//! (DEFOM-Stereo's Depth Anything V2): the ViT's linear layers, layer norms, GELU and attention,
//! and the DPT head's transposed convolutions. Opset 19 has no `Gelu` (opset 20) and no
//! `Attention` (opset 23), so these are written as the products and functions they are.

use burn::backend::ir::ScalarIr;
use burn::backend::ir::{AttentionOpIr, ConvTranspose2dOpIr, LayerNormOpIr, LinearOpIr, UnaryOpIr};
use dgstereo_core::{Error, Result};

use super::builder::Lowering;

/// `Linear`: `x · W + b`, burn's weight being `[inputs, outputs]` (ONNX's `MatMul` layout).
pub(super) fn linear(l: &mut Lowering, index: usize, op: &LinearOpIr) -> Result<()> {
    let inputs = vec![l.name(op.x.id), l.name(op.weight.id)];
    match &op.bias {
        None => {
            l.node(format!("n{index}"), "MatMul", inputs, vec![l.name(op.out.id)]);
        }
        Some(bias) => {
            let product = format!("n{index}_product");
            l.node(format!("n{index}_matmul"), "MatMul", inputs, vec![product.clone()]);
            l.node(format!("n{index}"), "Add", vec![product, l.name(bias.id)], vec![l.name(op.out.id)]);
        }
    }
    Ok(())
}

/// `LayerNorm` over the last axis: ONNX's `LayerNormalization` (opset 17), whose scale input is
/// burn's gamma and bias input its beta.
pub(super) fn layer_norm(l: &mut Lowering, index: usize, op: &LayerNormOpIr) -> Result<()> {
    let mut inputs = vec![l.name(op.input.id), l.name(op.gamma.id)];
    inputs.extend(op.beta.as_ref().map(|b| l.name(b.id)));
    let epsilon = op.epsilon.elem::<f64>() as f32;
    l.node(format!("n{index}"), "LayerNormalization", inputs, vec![l.name(op.out.id)])
        .int("axis", -1)
        .float("epsilon", epsilon);
    Ok(())
}

/// `Gelu`, the exact one burn computes: `x · (1 + erf(x / √2)) / 2`.
pub(super) fn gelu(l: &mut Lowering, index: usize, op: &UnaryOpIr) -> Result<()> {
    let dtype = op.input.dtype;
    let x = l.name(op.input.id);
    let root2 = l.scalar(format!("n{index}_sqrt2"), dtype, ScalarIr::Float(std::f64::consts::SQRT_2))?;
    let one = l.scalar(format!("n{index}_one"), dtype, ScalarIr::Float(1.0))?;
    let half = l.scalar(format!("n{index}_half"), dtype, ScalarIr::Float(0.5))?;
    let t = |s: &str| format!("n{index}_{s}");
    l.node(t("div"), "Div", vec![x.clone(), root2], vec![t("scaled")]);
    l.node(t("erf"), "Erf", vec![t("scaled")], vec![t("erf_out")]);
    l.node(t("add"), "Add", vec![t("erf_out"), one], vec![t("gate")]);
    l.node(t("mul"), "Mul", vec![x, t("gate")], vec![t("gated")]);
    l.node(format!("n{index}"), "Mul", vec![t("gated"), half], vec![l.name(op.out.id)]);
    Ok(())
}

/// Scaled dot-product attention on `[B, H, N, D]` queries, keys and values:
/// `softmax(q · kᵀ · scale) · v`, the scale `1/√D` unless the operation states one. A mask, a
/// bias, a causal mask or a soft cap is refused (no stereo model uses one).
pub(super) fn attention(l: &mut Lowering, index: usize, op: &AttentionOpIr) -> Result<()> {
    let o = &op.options;
    if op.mask.is_some() || op.attn_bias.is_some() || o.is_causal || o.softcap.is_some() {
        return Err(Error::unsupported(
            format!("ONNX export of operation {index} (Attention) with a mask, bias, causal mask or soft cap"),
            "the lowering writes plain scaled dot-product attention only",
        ));
    }
    let head_dim = op.query.shape[op.query.shape.num_dims() - 1];
    let scale = o.scale.map_or(1.0 / (head_dim as f64).sqrt(), |s| s.elem::<f64>());
    let rank = op.key.shape.num_dims();
    let mut perm: Vec<usize> = (0..rank).collect();
    perm.swap(rank - 2, rank - 1);
    let t = |s: &str| format!("n{index}_{s}");
    let scale = l.scalar(t("scale"), op.query.dtype, ScalarIr::Float(scale))?;
    l.node(t("key_t"), "Transpose", vec![l.name(op.key.id)], vec![t("keys")]).ints("perm", perm);
    l.node(t("scores"), "MatMul", vec![l.name(op.query.id), t("keys")], vec![t("logits")]);
    l.node(t("scaled"), "Mul", vec![t("logits"), scale], vec![t("scaled_logits")]);
    l.node(t("softmax"), "Softmax", vec![t("scaled_logits")], vec![t("weights")]).int("axis", -1);
    l.node(format!("n{index}"), "MatMul", vec![t("weights"), l.name(op.value.id)], vec![l.name(op.out.id)]);
    Ok(())
}

/// `ConvTranspose2d`: ONNX's `ConvTranspose`, whose weight layout (`[in, out / groups, kh, kw]`)
/// is burn's and PyTorch's.
pub(super) fn conv_transpose2d(l: &mut Lowering, index: usize, op: &ConvTranspose2dOpIr) -> Result<()> {
    let mut inputs = vec![l.name(op.x.id), l.name(op.weight.id)];
    inputs.extend(op.bias.as_ref().map(|b| l.name(b.id)));
    let o = &op.options;
    let [kh, kw] = [op.weight.shape[2], op.weight.shape[3]];
    l.node(format!("n{index}"), "ConvTranspose", inputs, vec![l.name(op.out.id)])
        .ints("kernel_shape", [kh, kw])
        .ints("strides", o.stride)
        .ints("dilations", o.dilation)
        .ints("pads", [o.padding[0], o.padding[1], o.padding[0], o.padding[1]])
        .ints("output_padding", o.padding_out)
        .int("group", o.groups as i64);
    Ok(())
}
