//! Depth Anything V2 as DEFOM-Stereo embeds it: the network inside the stereo network, handing
//! its features to the encoders and its inverse depth to the disparity initialiser.
//!
//! DEFOM-Stereo (Jiang et al., CVPR 2025) modifies the official `dpt.py`: beside the usual
//! depth head (`depth_head`) a second DPT trunk (`depth_feat`, DEFOM's `DPTFeat`: reassembly,
//! channel adapters and fusion blocks, no output convolutions) returns the left view's adapted
//! levels resized to the update grid and its halves and quarters (the context encoder's three
//! levels), and both views' finest fused level (the feature encoder's). Its fusion blocks keep
//! the finest level's size (the modified `blocks.py` drops the last block's 2x upsampling), and
//! the depth head runs on the left view only and resizes to the update grid. The network takes
//! both views, already ImageNet-normalised, resized (bilinear, align corners) to
//! [`io_size`]: 3.5 times the update grid, rounded up to multiples of 14.
//!
//! Field names are the official ones below `defomencoder.depth_anything.`.

use burn::module::Module;
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::tensor::{Device, Tensor};
use dgstereo_core::MonocularFeatures;
use dgstereo_kernels::resize_bilinear;

use super::checkpoint::{PartialLoad, load_partial_into};
use super::dinov2::{DinoVisionTransformer, IntermediateLayer, PATCH_SIZE};
use super::dpt::{DptHead, FeatureFusionBlock, adapt, conv, conv_transpose, reassemble, spatial};
use super::encoder::DepthAnythingV2Encoder;

/// The largest input side DEFOM-Stereo gives the network (`max_i_size`, a multiple of 14).
pub const MAX_INPUT_SIDE: usize = 2688;

/// DEFOM-Stereo's `get_danv2_io_size`: the network's input size `[ih, iw]` and output size (the
/// update grid) `[oh, ow]` for images of `h x w` and an update grid at `1/2^n_downsample`.
///
/// The output is `h >> n_downsample` by `w >> n_downsample`; the input is 3.5 times it (14 / 4,
/// the patch size over the grid's stride in DPT's finest level), each side rounded up to a
/// multiple of 14; where a side would exceed [`MAX_INPUT_SIDE`] the longer side is set to it and
/// the other scaled by the same factor, rounded up to a multiple of 14.
pub fn io_size(h: usize, w: usize, n_downsample: usize) -> ([usize; 2], [usize; 2]) {
    let (oh, ow) = (h >> n_downsample, w >> n_downsample);
    let m = PATCH_SIZE as f64;
    let up = |x: f64| ((x / m).ceil() * m) as usize;
    let (ih, iw) = (up(3.5 * oh as f64), up(3.5 * ow as f64));
    let max = MAX_INPUT_SIDE;
    let input = if ih <= max && iw <= max {
        [ih, iw]
    } else {
        let (factor_h, factor_w) = (max as f64 / ih as f64, max as f64 / iw as f64);
        if factor_w > factor_h { [max, up(factor_h * iw as f64)] } else { [up(factor_w * ih as f64), max] }
    };
    (input, [oh, ow])
}

/// Channel adapters and fusion blocks of [`DptFeatures`] (`depth_feat.scratch.*`).
#[derive(Module, Debug)]
pub struct FeatureScratch {
    /// 3x3 conv, no bias, level 1.
    pub layer1_rn: Conv2d,
    /// Level 2.
    pub layer2_rn: Conv2d,
    /// Level 3.
    pub layer3_rn: Conv2d,
    /// Level 4.
    pub layer4_rn: Conv2d,
    /// Finest fusion block.
    pub refinenet1: FeatureFusionBlock,
    /// Fusion block 2.
    pub refinenet2: FeatureFusionBlock,
    /// Fusion block 3.
    pub refinenet3: FeatureFusionBlock,
    /// Coarsest fusion block (no skip input).
    pub refinenet4: FeatureFusionBlock,
}

/// DEFOM-Stereo's `DPTFeat` (`depth_feat.*`): a DPT trunk without output convolutions.
#[derive(Module, Debug)]
pub struct DptFeatures {
    /// 1x1 convs from the token width to each level's channels.
    pub projects: Vec<Conv2d>,
    /// Level 1 resize (`resize_layers.0`): transposed conv, 4x.
    pub upsample_4x: ConvTranspose2d,
    /// Level 2 resize (`resize_layers.1`): transposed conv, 2x.
    pub upsample_2x: ConvTranspose2d,
    /// Level 4 resize (`resize_layers.3`): 3x3 conv, stride 2.
    pub downsample_2x: Conv2d,
    /// Adapters and fusion.
    pub scratch: FeatureScratch,
}

/// The context levels, then the left and right views' finest fused level.
type FeatureMaps = (Vec<Tensor<4>>, Tensor<4>, Tensor<4>);

impl DptFeatures {
    /// A randomly initialised trunk reading tokens of width `in_channels`.
    pub fn new(in_channels: usize, features: usize, out_channels: [usize; 4], device: &Device) -> Self {
        let fusion = || FeatureFusionBlock::new(features, device);
        Self {
            projects: out_channels.iter().map(|&c| conv(in_channels, c, 1, 1, true, device)).collect(),
            upsample_4x: conv_transpose(out_channels[0], 4, device),
            upsample_2x: conv_transpose(out_channels[1], 2, device),
            downsample_2x: conv(out_channels[3], out_channels[3], 3, 2, true, device),
            scratch: FeatureScratch {
                layer1_rn: conv(out_channels[0], features, 3, 1, false, device),
                layer2_rn: conv(out_channels[1], features, 3, 1, false, device),
                layer3_rn: conv(out_channels[2], features, 3, 1, false, device),
                layer4_rn: conv(out_channels[3], features, 3, 1, false, device),
                refinenet1: fusion(),
                refinenet2: fusion(),
                refinenet3: fusion(),
                refinenet4: fusion(),
            },
        }
    }

    /// The left view's three context levels (the adapted levels 1..3 resized to `out_size`, its
    /// half and its quarter), and both views' finest fused level at `out_size`. The layers hold
    /// the `batch` left views, then the right ones.
    ///
    /// # Shapes
    /// - `layers[i].tokens`: `[2·batch, h·w, C]`
    /// - context `[batch, F, out_size / 2^l]`; left and right `[batch, F, out_size]`
    pub fn forward(
        &self,
        layers: &[IntermediateLayer],
        grid: [usize; 2],
        batch: usize,
        out_size: [usize; 2],
    ) -> FeatureMaps {
        let resize = [&self.upsample_4x, &self.upsample_2x];
        let levels = reassemble(&self.projects, resize, &self.downsample_2x, layers, grid, None);
        let s = &self.scratch;
        let adapted = adapt([&s.layer1_rn, &s.layer2_rn, &s.layer3_rn, &s.layer4_rn], levels);
        let [oh, ow] = out_size;
        let mut sizes = (0..4).map(|l| [oh >> l, ow >> l]);
        let [l1, l2, l3, l4] = adapted.map(|level| resize_bilinear(level, sizes.next().expect("four sizes"), true));
        let context = [&l1, &l2, &l3].iter().map(|l| (*l).clone().narrow(0, 0, batch)).collect();
        let path = s.refinenet4.forward(l4, None, spatial(&l3));
        let path = s.refinenet3.forward(path, Some(l3), spatial(&l2));
        let path = s.refinenet2.forward(path, Some(l2), spatial(&l1));
        let size = spatial(&l1);
        let path = s.refinenet1.forward(path, Some(l1), size);
        (context, path.clone().narrow(0, 0, batch), path.narrow(0, batch, batch))
    }
}

/// Depth Anything V2 with DEFOM-Stereo's two heads (`defomencoder.depth_anything.*` in its
/// checkpoints).
#[derive(Module, Debug)]
pub struct DepthAnythingV2Features {
    /// The ViT encoder (`pretrained.*`).
    pub pretrained: DinoVisionTransformer,
    /// The depth head (`depth_head.*`), run by DEFOM's rules ([`DptHead::inverse_depth_at`]).
    pub depth_head: DptHead,
    /// The feature trunk (`depth_feat.*`).
    pub depth_feat: DptFeatures,
    #[module(skip)]
    encoder: DepthAnythingV2Encoder,
}

impl DepthAnythingV2Features {
    /// A randomly initialised network of size `encoder` (real use loads a checkpoint).
    pub fn new(encoder: DepthAnythingV2Encoder, device: &Device) -> Self {
        let vit = encoder.vit();
        let (features, out_channels) = (encoder.features(), encoder.out_channels());
        Self {
            pretrained: DinoVisionTransformer::new(vit, device),
            depth_head: DptHead::new(vit.embed_dim, features, out_channels, device),
            depth_feat: DptFeatures::new(vit.embed_dim, features, out_channels, device),
            encoder,
        }
    }

    /// The encoder size.
    pub fn encoder(&self) -> DepthAnythingV2Encoder {
        self.encoder
    }

    /// The width `F` of the features it hands on (`features`: 64, 128, 256).
    pub fn feature_channels(&self) -> usize {
        self.encoder.features()
    }

    /// Loads an official Depth Anything V2 checkpoint (`depth_anything_v2_vit{s,b,l}.pth`) as
    /// DEFOM-Stereo's `DefomEncoder` does before training (`strict=False`): the ViT
    /// (`pretrained.*`) and the depth head (`depth_head.*`) come from the file and must all be
    /// there with their shapes; the feature trunk (`depth_feat.*`), which such a file lacks,
    /// keeps its values, and keys the network lacks are ignored.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Io`] when the file is missing, [`dgstereo_core::Error::Checkpoint`]
    /// naming the first key of another shape (a checkpoint of another size) or the first ViT or
    /// head key the file lacks.
    pub fn load_depth_anything(&mut self, weights: &std::path::Path) -> dgstereo_core::Result<PartialLoad> {
        let encoder = self.encoder;
        load_partial_into(self, encoder, weights, &["pretrained.", "depth_head."])
    }

    /// DEFOM-Stereo's `DefomEncoder` up to the disparity initialisation: both views (ImageNet-
    /// normalised, as the stereo encoders see them) resized to [`io_size`], the ViT, the feature
    /// trunk and the depth head, for an update grid at `1/2^n_downsample`.
    ///
    /// # Shapes
    /// - `left`, `right`: `[N, 3, H, W]`; output: see [`MonocularFeatures`]
    pub fn features(&self, left: Tensor<4>, right: Tensor<4>, n_downsample: usize) -> MonocularFeatures {
        let [n, _, h, w] = left.dims();
        let ([ih, iw], out_size) = io_size(h, w, n_downsample);
        let x = resize_bilinear(Tensor::cat(vec![left, right], 0), [ih, iw], true);
        let grid = [ih / PATCH_SIZE, iw / PATCH_SIZE];
        let layers = self.pretrained.intermediate_layers(x, &self.encoder.intermediate_layers());
        let (context, left, right) = self.depth_feat.forward(&layers, grid, n, out_size);
        let inverse_depth = self.depth_head.inverse_depth_at(&layers, grid, n, out_size);
        MonocularFeatures { context, left, right, inverse_depth }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `get_danv2_io_size` written out in the official code's own terms (numpy floats).
    fn official(h: usize, w: usize, nds: usize) -> (usize, usize, usize, usize) {
        let (oh, ow) = (h / (1 << nds), w / (1 << nds));
        let ceil14 = |x: f64| ((x / 14.0).ceil() * 14.0) as usize;
        let (ih, iw) = (ceil14(3.5 * oh as f64), ceil14(3.5 * ow as f64));
        let max = ((2688.0f64 / 14.0).floor() * 14.0) as usize;
        if ih <= max && iw <= max {
            return (ih, iw, oh, ow);
        }
        let (fh, fw) = (max as f64 / ih as f64, max as f64 / iw as f64);
        if fw > fh { (max, ceil14(fh * iw as f64), oh, ow) } else { (ceil14(fw * ih as f64), max, oh, ow) }
    }

    #[test]
    fn io_sizes_are_the_official_ones() {
        // The golden's 96x128 pair: a 24x32 grid, 84x112 in (6x8 patches).
        assert_eq!(io_size(96, 128, 2), ([84, 112], [24, 32]));
        // 384x448 (the benchmark size): 96x112 -> 336x392.
        assert_eq!(io_size(384, 448, 2), ([336, 392], [96, 112]));
        // 3.5 x 800 > 2688: the width is capped and the height scaled by 2688 / 2800 = 0.96.
        assert_eq!(io_size(2016, 3200, 2), ([1694, 2688], [504, 800]));
        for (h, w, nds) in [(96, 128, 2), (100, 130, 2), (544, 960, 2), (2016, 3200, 2), (3200, 640, 2), (64, 64, 3)] {
            let ([ih, iw], [oh, ow]) = io_size(h, w, nds);
            assert_eq!((ih, iw, oh, ow), official(h, w, nds), "{h}x{w} at 1/{}", 1 << nds);
            assert!(ih % 14 == 0 && iw % 14 == 0);
        }
    }
}
