//! Operation counts of the network, per stage, from its configuration and the input size.
//!
//! Design decision: only the multiply-accumulates of convolutions and matrix products are
//! counted (one MAC = 2 FLOP). They are more than 99 % of the arithmetic, and they are what a
//! machine's peak (a large float32 matrix product) measures, so "achieved GFLOP/s" compares
//! directly with that peak. Normalisations, activations, the correlation lookup and the convex
//! upsampling's softmax are element-wise or memory-bound; they are counted as zero, so the
//! stages made of them show their time with no GFLOP/s. The counts follow the module layout of
//! [`crate::RaftStereo::new`] (same widths, strides and kernel sizes) and are checked against a
//! hand count of the reference's layers in the tests.

use crate::ModelConfig;

/// MACs of one convolution producing a `h_out x w_out` map per image.
pub fn conv_macs(c_in: usize, c_out: usize, kernel: usize, h_out: usize, w_out: usize) -> u64 {
    (c_in * c_out * kernel * kernel) as u64 * (h_out * w_out) as u64
}

/// The multiply-accumulates of each stage of one forward pass (batch of one pair).
///
/// Per-iteration stages hold the cost of a single iteration; [`StageMacs::forward`] multiplies
/// them by the iteration count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageMacs {
    /// Feature encoder on both images.
    pub feature_encoder: u64,
    /// Context encoder on the left image, with the context-to-gate convolutions.
    pub context_encoder: u64,
    /// All-pairs correlation (one batched matrix product; pooling not counted).
    pub correlation_build: u64,
    /// Motion encoder, per iteration.
    pub motion_encoder: u64,
    /// GRU at 1/f, per iteration.
    pub gru_fine: u64,
    /// GRU at 1/(2f), per iteration.
    pub gru_mid: u64,
    /// GRU at 1/(4f), per iteration.
    pub gru_coarse: u64,
    /// Disparity head, per iteration.
    pub flow_head: u64,
    /// Upsampling-weight head, per upsampled iteration.
    pub mask_head: u64,
    /// Convex combination of the upsampling, per upsampled iteration.
    pub convex_upsample: u64,
    /// Bilinear resizes between GRU levels (matrix products), per iteration.
    pub interpolation: u64,
}

/// Output side of a `k x k` convolution with padding `k / 2` and `stride` (PyTorch's formula).
fn out_size(n: usize, kernel: usize, stride: usize) -> usize {
    (n + 2 * (kernel / 2) - kernel) / stride + 1
}

/// MACs of one residual block at input size `[h, w]`; returns them and the output size.
fn residual_block(c_in: usize, c_out: usize, stride: usize, [h, w]: [usize; 2]) -> (u64, [usize; 2]) {
    let (ho, wo) = (out_size(h, 3, stride), out_size(w, 3, stride));
    let mut macs = conv_macs(c_in, c_out, 3, ho, wo) + conv_macs(c_out, c_out, 3, ho, wo);
    if stride != 1 || c_in != c_out {
        macs += conv_macs(c_in, c_out, 1, ho, wo);
    }
    (macs, [ho, wo])
}

/// A layer of two blocks (`_make_layer`).
fn layer(c_in: usize, c_out: usize, stride: usize, size: [usize; 2]) -> (u64, [usize; 2]) {
    let (a, size) = residual_block(c_in, c_out, stride, size);
    let (b, size) = residual_block(c_out, c_out, 1, size);
    (a + b, size)
}

/// The shared trunk (conv1, layer1..3) of both encoders; returns MACs and the 1/f size.
fn trunk(n_downsample: usize, [c1, c2, c3]: [usize; 3], [h, w]: [usize; 2]) -> (u64, [usize; 2]) {
    let s1 = 1 + (n_downsample > 2) as usize;
    let s2 = 1 + (n_downsample > 1) as usize;
    let s3 = 1 + (n_downsample > 0) as usize;
    let size = [out_size(h, 7, s1), out_size(w, 7, s1)];
    let mut macs = conv_macs(3, c1, 7, size[0], size[1]);
    let (m1, size) = layer(c1, c1, 1, size);
    let (m2, size) = layer(c1, c2, s2, size);
    let (m3, size) = layer(c2, c3, s3, size);
    macs += m1 + m2 + m3;
    (macs, size)
}

impl StageMacs {
    /// The counts for a `[h, w]` input (already padded to a multiple of 32) under `config`.
    pub fn new(config: &ModelConfig, [h, w]: [usize; 2]) -> Self {
        let u = &config.updater;
        let [d32, d16, d08] = u.hidden_dims;
        let n = u.n_gru_layers;
        let (trunk_macs, [h4, w4]) = trunk(u.n_downsample, config.encoder.trunk_dims, [h, w]);
        let tc = config.encoder.trunk_dims[2];
        let (h8, w8) = (out_size(h4, 3, 2), out_size(w4, 3, 2));
        let (h16, w16) = (out_size(h8, 3, 2), out_size(w8, 3, 2));
        let fdim = config.encoder.feature_dim;

        let (feature_encoder, mut context_encoder) = if config.encoder.shared_backbone {
            // One trunk on both images; the feature head (block + 3x3) on both.
            let head = residual_block(tc, tc, 1, [h4, w4]).0 + conv_macs(tc, fdim, 3, h4, w4);
            (2 * head, 2 * trunk_macs)
        } else {
            (2 * (trunk_macs + conv_macs(tc, fdim, 1, h4, w4)), trunk_macs)
        };
        // Heads: per level two (block + 3x3), the coarsest two plain 3x3 convolutions.
        let head =
            |dim: usize, [hh, ww]: [usize; 2]| residual_block(tc, tc, 1, [hh, ww]).0 + conv_macs(tc, dim, 3, hh, ww);
        context_encoder += 2 * head(d08, [h4, w4]) + conv_macs(d08, 3 * d08, 3, h4, w4);
        if n >= 2 {
            context_encoder += layer(tc, tc, 2, [h4, w4]).0 + 2 * head(d16, [h8, w8]);
            context_encoder += conv_macs(d16, 3 * d16, 3, h8, w8);
        }
        if n >= 3 {
            context_encoder += layer(tc, tc, 2, [h8, w8]).0 + 2 * conv_macs(tc, d32, 3, h16, w16);
            context_encoder += conv_macs(d32, 3 * d32, 3, h16, w16);
        }

        let corr_channels = config.correlation.channels();
        let guided = u.guidance.channels();
        let mut motion_encoder = conv_macs(corr_channels, 64, 1, h4, w4)
            + conv_macs(64, 64, 3, h4, w4)
            + conv_macs(2, 64, 7, h4, w4)
            + conv_macs(64, 64, 3, h4, w4)
            + conv_macs(64 * (2 + (guided > 0) as usize), 126, 3, h4, w4);
        if guided > 0 {
            motion_encoder += conv_macs(guided, 64, 7, h4, w4) + conv_macs(64, 64, 3, h4, w4);
        }
        let gru = |hidden: usize, input: usize, hh: usize, ww: usize| 3 * conv_macs(hidden + input, hidden, 3, hh, ww);
        let gru_fine = gru(d08, 128 + d16 * (n > 1) as usize, h4, w4);
        let gru_mid = if n >= 2 { gru(d16, d32 * (n == 3) as usize + d08, h8, w8) } else { 0 };
        let gru_coarse = if n >= 3 { gru(d32, d16, h16, w16) } else { 0 };
        let factor = 1usize << u.n_downsample;
        // Resizes: 1/8 -> 1/4 for the fine GRU, 1/16 -> 1/8 for the middle one (rows then columns).
        let resize =
            |c: usize, [hi, wi]: [usize; 2], [ho, wo]: [usize; 2]| (c * ho * hi * wi + c * ho * wi * wo) as u64;
        let mut interpolation = 0;
        if n >= 2 {
            interpolation += resize(d16, [h8, w8], [h4, w4]);
        }
        if n >= 3 {
            interpolation += resize(d32, [h16, w16], [h8, w8]);
        }
        Self {
            feature_encoder,
            context_encoder,
            correlation_build: (h4 * w4 * w4 * fdim) as u64,
            motion_encoder,
            gru_fine,
            gru_mid,
            gru_coarse,
            flow_head: conv_macs(d08, 256, 3, h4, w4) + conv_macs(256, 2, 3, h4, w4),
            mask_head: conv_macs(d08, 256, 3, h4, w4) + conv_macs(256, 9 * factor * factor, 1, h4, w4),
            convex_upsample: (9 * factor * factor * h4 * w4) as u64,
            interpolation,
        }
    }

    /// MACs of one update iteration without the mask head and upsampling.
    pub fn iteration(&self) -> u64 {
        self.motion_encoder + self.gru_fine + self.gru_mid + self.gru_coarse + self.flow_head + self.interpolation
    }

    /// MACs of a whole forward pass of `iters` iterations, `upsampled` of which are upsampled
    /// to full resolution (1 for inference, `iters` for training).
    pub fn forward(&self, iters: usize, upsampled: usize) -> u64 {
        self.feature_encoder
            + self.context_encoder
            + self.correlation_build
            + iters as u64 * self.iteration()
            + upsampled as u64 * (self.mask_head + self.convex_upsample)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fine GRU and the mask head at a 96x112 grid, counted by hand from the reference's
    /// layers: three 3x3 convolutions of 384 -> 128 channels; 3x3 128 -> 256 and 1x1 256 -> 144.
    #[test]
    fn update_stages_match_a_hand_count() {
        let m = StageMacs::new(&ModelConfig::default(), [384, 448]);
        let px = 96 * 112u64;
        assert_eq!(m.gru_fine, 3 * 384 * 128 * 9 * px);
        assert_eq!(m.mask_head, (128 * 256 * 9 + 256 * 144) * px);
        assert_eq!(m.gru_mid, 3 * (128 + 256) * 128 * 9 * 48 * 56);
        assert_eq!(m.correlation_build, 96 * 112 * 112 * 256);
    }

    /// The feature encoder of one image, by hand: stem at full resolution (stride 1 when
    /// `n_downsample = 2`), layer1 there, layer2 and layer3 halving, the 1x1 projection.
    #[test]
    fn feature_encoder_matches_a_hand_count() {
        let (h, w) = (64u64, 128u64);
        let m = StageMacs::new(&ModelConfig::default(), [64, 128]);
        let full = h * w;
        let stem = 3 * 64 * 49 * full;
        let layer1 = 4 * 64 * 64 * 9 * full;
        let half = full / 4;
        let layer2 = (64 * 96 * 9 + 3 * 96 * 96 * 9 + 64 * 96) * half;
        let quarter = full / 16;
        let layer3 = (96 * 128 * 9 + 3 * 128 * 128 * 9 + 96 * 128) * quarter;
        let proj = 128 * 256 * quarter;
        assert_eq!(m.feature_encoder, 2 * (stem + layer1 + layer2 + layer3 + proj));
    }

    /// Fewer GRU levels drop the coarse GRUs and shrink the fine GRU's input.
    #[test]
    fn fewer_levels_cost_less() {
        let mut config = ModelConfig::default();
        let three = StageMacs::new(&config, [256, 256]);
        config.updater.n_gru_layers = 1;
        let one = StageMacs::new(&config, [256, 256]);
        assert_eq!(one.gru_mid + one.gru_coarse + one.interpolation, 0);
        assert!(one.gru_fine < three.gru_fine);
        assert!(one.forward(32, 1) < three.forward(32, 1));
        assert_eq!(three.forward(2, 1) - three.forward(1, 1), three.iteration());
    }
}
