//! The DINOv2 ViT encoder of Depth Anything V2 (`pretrained.*` in the checkpoints).
//!
//! A plain pre-norm ViT: a 14x14 patch embedding, a class token, a learned position embedding
//! for a 37x37 grid (518 px) that is bicubically resized to the input's grid, and `depth` blocks
//! `x += ls1 · attn(norm1(x)); x += ls2 · mlp(norm2(x))`. Depth Anything reads four intermediate
//! blocks, each passed through the final norm, as `get_intermediate_layers(..., norm=True,
//! return_class_token=True)` does. No register tokens, no masking at inference (`mask_token` is
//! kept only because the checkpoints hold it).

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::activation::gelu;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{Device, Tensor};

use super::cubic::resize_bicubic_with_ratio;
use dgstereo_kernels::linear_forward;

/// The patch size of every DINOv2 variant.
pub const PATCH_SIZE: usize = 14;
/// The side of the position-embedding grid the checkpoints were trained with (518 / 14).
pub const POS_EMBED_GRID: usize = 37;
/// DINOv2's offset added to the target grid before computing the resize scale factor.
const INTERPOLATE_OFFSET: f64 = 0.1;
/// LayerNorm epsilon of DINOv2 (`partial(nn.LayerNorm, eps=1e-6)`).
const NORM_EPS: f64 = 1e-6;

/// The size of a ViT variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VitSpec {
    /// Token width.
    pub embed_dim: usize,
    /// Number of blocks.
    pub depth: usize,
    /// Attention heads.
    pub heads: usize,
}

/// Learned per-channel scaling of a residual branch (`ls1`, `ls2`).
#[derive(Module, Debug)]
pub struct LayerScale {
    /// The per-channel factor (`gamma` in the checkpoints).
    pub gamma: Param<Tensor<1>>,
}

impl LayerScale {
    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        x * self.gamma.val().unsqueeze::<3>()
    }
}

/// Multi-head self-attention with a fused `qkv` projection.
#[derive(Module, Debug)]
pub struct Attention {
    /// `C -> 3C` projection to queries, keys and values.
    pub qkv: Linear,
    /// Output projection `C -> C`.
    pub proj: Linear,
    heads: usize,
}

impl Attention {
    /// # Shapes
    /// - `x`: `[B, N, C]` -> `[B, N, C]`
    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let [b, n, c] = x.dims();
        let head_dim = c / self.heads;
        let qkv = linear_forward(&self.qkv, x).reshape([b, n, 3, self.heads, head_dim]).permute([2, 0, 3, 1, 4]);
        let take = |i: usize| qkv.clone().narrow(0, i, 1).squeeze_dim::<4>(0);
        let (q, k, v) = (take(0), take(1), take(2));
        // burn's fused attention (scale 1/sqrt(head_dim) by default): on the CPU its flash kernel
        // runs the heads in parallel with an online softmax; the prior took 9.2-10.5 s with
        // `softmax(q·kᵀ)·v` composed of tensor operations and 7.6 s with it (ViT-S on both views
        // of a 900x750 pair).
        let out = attention(q, k, v, None, None, AttentionModuleOptions::default());
        let out = out.swap_dims(1, 2).reshape([b, n, c]);
        linear_forward(&self.proj, out)
    }
}

/// The two-layer GELU MLP of a block (ratio 4).
#[derive(Module, Debug)]
pub struct Mlp {
    /// `C -> 4C`.
    pub fc1: Linear,
    /// `4C -> C`.
    pub fc2: Linear,
}

/// One pre-norm transformer block with layer scale.
#[derive(Module, Debug)]
pub struct Block {
    /// Norm before attention.
    pub norm1: LayerNorm,
    /// Self-attention.
    pub attn: Attention,
    /// Layer scale of the attention branch.
    pub ls1: LayerScale,
    /// Norm before the MLP.
    pub norm2: LayerNorm,
    /// Feed-forward network.
    pub mlp: Mlp,
    /// Layer scale of the MLP branch.
    pub ls2: LayerScale,
}

impl Block {
    fn new(spec: VitSpec, device: &Device) -> Self {
        let c = spec.embed_dim;
        let norm = || LayerNormConfig::new(c).with_epsilon(NORM_EPS).init(device);
        let scale = || LayerScale { gamma: Param::from_tensor(Tensor::ones([c], device)) };
        Self {
            norm1: norm(),
            attn: Attention {
                qkv: LinearConfig::new(c, 3 * c).init(device),
                proj: LinearConfig::new(c, c).init(device),
                heads: spec.heads,
            },
            ls1: scale(),
            norm2: norm(),
            mlp: Mlp { fc1: LinearConfig::new(c, 4 * c).init(device), fc2: LinearConfig::new(4 * c, c).init(device) },
            ls2: scale(),
        }
    }

    /// # Shapes
    /// - `x`: `[B, N, C]` -> `[B, N, C]`
    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let x = x.clone() + self.ls1.forward(self.attn.forward(self.norm1.forward(x)));
        let hidden = gelu(linear_forward(&self.mlp.fc1, self.norm2.forward(x.clone())));
        x + self.ls2.forward(linear_forward(&self.mlp.fc2, hidden))
    }
}

/// The patch embedding: a `14x14` convolution with stride 14.
#[derive(Module, Debug)]
pub struct PatchEmbed {
    /// `3 -> C` convolution.
    pub proj: Conv2d,
}

/// One intermediate output of the encoder, after the final norm.
#[derive(Debug, Clone)]
pub struct IntermediateLayer {
    /// Patch tokens, row-major over the patch grid: `[B, h·w, C]`.
    pub tokens: Tensor<3>,
    /// The class token: `[B, C]`.
    pub cls: Tensor<2>,
}

/// The DINOv2 vision transformer.
#[derive(Module, Debug)]
pub struct DinoVisionTransformer {
    /// Class token, `[1, 1, C]`.
    pub cls_token: Param<Tensor<3>>,
    /// Position embedding of the class token and a 37x37 patch grid, `[1, 1 + 37², C]`.
    pub pos_embed: Param<Tensor<3>>,
    /// Mask token of DINOv2's masked training, `[1, C]`; unused at inference.
    pub mask_token: Param<Tensor<2>>,
    /// Patch embedding.
    pub patch_embed: PatchEmbed,
    /// Transformer blocks.
    pub blocks: Vec<Block>,
    /// Final LayerNorm, applied to every intermediate output.
    pub norm: LayerNorm,
}

impl DinoVisionTransformer {
    /// A randomly initialised encoder of size `spec`.
    pub fn new(spec: VitSpec, device: &Device) -> Self {
        let c = spec.embed_dim;
        let tokens = 1 + POS_EMBED_GRID * POS_EMBED_GRID;
        let normal = burn::tensor::Distribution::Normal(0.0, 0.02);
        Self {
            cls_token: Param::from_tensor(Tensor::random([1, 1, c], normal, device)),
            pos_embed: Param::from_tensor(Tensor::random([1, tokens, c], normal, device)),
            mask_token: Param::from_tensor(Tensor::zeros([1, c], device)),
            patch_embed: PatchEmbed {
                proj: Conv2dConfig::new([3, c], [PATCH_SIZE, PATCH_SIZE])
                    .with_stride([PATCH_SIZE, PATCH_SIZE])
                    .init(device),
            },
            blocks: (0..spec.depth).map(|_| Block::new(spec, device)).collect(),
            norm: LayerNormConfig::new(c).with_epsilon(NORM_EPS).init(device),
        }
    }

    /// The position embedding resized to a `grid = [h, w]` patch grid, as DINOv2's
    /// `interpolate_pos_encoding`: bicubic with scale factors `(grid + 0.1) / 37`, which PyTorch
    /// turns into the output size `floor(37 · factor) = grid` and the source ratio `1 / factor`.
    ///
    /// # Shapes
    /// - output: `[1, 1 + h·w, C]`
    pub fn position_embedding(&self, grid: [usize; 2]) -> Tensor<3> {
        let pos = self.pos_embed.val();
        let [_, tokens, c] = pos.dims();
        let side = ((tokens - 1) as f64).sqrt() as usize;
        if grid == [side, side] {
            return pos;
        }
        let class_pos = pos.clone().narrow(1, 0, 1);
        let patch_pos = pos.narrow(1, 1, tokens - 1).reshape([1, side, side, c]).permute([0, 3, 1, 2]);
        // PyTorch: ratio = (float)(1.0 / scale_factor), computed in double.
        let ratio = grid.map(|g| (1.0 / ((g as f64 + INTERPOLATE_OFFSET) / side as f64)) as f32);
        let resized = resize_bicubic_with_ratio(patch_pos, grid, ratio);
        let patch_pos = resized.permute([0, 2, 3, 1]).reshape([1, grid[0] * grid[1], c]);
        Tensor::cat(vec![class_pos, patch_pos], 1)
    }

    /// Patch embedding, class token and position embedding.
    ///
    /// # Shapes
    /// - `x`: `[B, 3, H, W]` with `H`, `W` multiples of 14
    /// - output: `[B, 1 + (H/14)·(W/14), C]`
    pub fn prepare_tokens(&self, x: Tensor<4>) -> Tensor<3> {
        let [b, _, h, w] = x.dims();
        let grid = [h / PATCH_SIZE, w / PATCH_SIZE];
        let patches = self.patch_embed.proj.forward(x);
        let [_, c, _, _] = patches.dims();
        let patches = patches.reshape([b, c, grid[0] * grid[1]]).swap_dims(1, 2);
        let cls = self.cls_token.val().expand([b, 1, c]);
        Tensor::cat(vec![cls, patches], 1) + self.position_embedding(grid)
    }

    /// The normed outputs of blocks `layers` (0-based), as
    /// `get_intermediate_layers(x, layers, return_class_token=True)`.
    ///
    /// # Shapes
    /// - `x`: `[B, 3, H, W]` with `H`, `W` multiples of 14
    /// - each output: tokens `[B, (H/14)·(W/14), C]`, cls `[B, C]`
    pub fn intermediate_layers(&self, x: Tensor<4>, layers: &[usize]) -> Vec<IntermediateLayer> {
        let mut x = self.prepare_tokens(x);
        let last = layers.iter().copied().max().unwrap_or(0);
        let mut outputs = Vec::with_capacity(layers.len());
        for (i, block) in self.blocks.iter().enumerate().take(last + 1) {
            x = block.forward(x);
            if layers.contains(&i) {
                let normed = self.norm.forward(x.clone());
                let [b, n, c] = normed.dims();
                outputs.push(IntermediateLayer {
                    cls: normed.clone().narrow(1, 0, 1).reshape([b, c]),
                    tokens: normed.narrow(1, 1, n - 1),
                });
            }
        }
        outputs
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use burn::tensor::activation::softmax;
    use dgstereo_core::tensor::max_abs_diff;

    use super::*;

    /// The attention module (burn's fused attention) against `softmax(q·kᵀ/√d)·v` from tensor
    /// operations, at a sequence long enough for burn's flash kernel (more than 512 keys; the
    /// golden file's 35 tokens take its other path) and a short one.
    #[test]
    fn fused_attention_equals_the_composed_softmax() {
        let device = Device::flex();
        for tokens in [35, 700] {
            let attn = Attention {
                qkv: LinearConfig::new(32, 96).init(&device),
                proj: LinearConfig::new(32, 32).init(&device),
                heads: 2,
            };
            let x = Tensor::<3>::random([2, tokens, 32], Distribution::Normal(0.0, 1.0), &device);
            let qkv = attn.qkv.forward(x.clone()).reshape([2, tokens, 3, 2, 16]).permute([2, 0, 3, 1, 4]);
            let take = |i: usize| qkv.clone().narrow(0, i, 1).squeeze_dim::<4>(0);
            let scores = take(0).mul_scalar(0.25).matmul(take(1).swap_dims(2, 3));
            let composed = softmax(scores, 3).matmul(take(2)).swap_dims(1, 2).reshape([2, tokens, 32]);
            let want = attn.proj.forward(composed);
            let got = attn.forward(x);
            let err = max_abs_diff(got, want.clone());
            let scale: f32 = want.abs().max().into_scalar();
            assert!(err <= 1e-5 * scale, "{tokens} tokens: max error {err} of {scale}");
        }
    }
}
