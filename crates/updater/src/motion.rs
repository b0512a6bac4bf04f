//! The motion encoder: correlation, current disparity and (optionally) depth guidance merged
//! into the GRU's input.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::conv2d_relu_forward;

use crate::loop_numerics::UPDATE_LOOP;

/// Correlation branch (1x1, 3x3), flow branch (7x7, 3x3) and an optional guidance branch
/// (7x7, 3x3) joined by a 3x3 merge convolution; the 2-channel flow is appended to the output.
///
/// # Shapes
/// - `corr`: `[N, corr_channels, H, W]`, `flow`: `[N, 2, H, W]`, `guidance`: `[N, g, H, W]`
/// - output: `[N, 128, H, W]`
#[derive(Module, Debug)]
pub struct MotionEncoder {
    /// 1x1 on the correlation.
    pub convc1: Conv2d,
    /// 3x3 on the correlation branch.
    pub convc2: Conv2d,
    /// 7x7 on the flow.
    pub convf1: Conv2d,
    /// 3x3 on the flow branch.
    pub convf2: Conv2d,
    /// 7x7 on the guidance (the paper's Gradient-GRU); absent in RAFT-Stereo.
    pub convg1: Option<Conv2d>,
    /// 3x3 on the guidance branch.
    pub convg2: Option<Conv2d>,
    /// Merge convolution to 126 channels.
    pub conv: Conv2d,
}

impl MotionEncoder {
    /// The encoder for `corr_channels` correlation channels and `guidance_channels` (0 = none).
    pub fn new(corr_channels: usize, guidance_channels: usize, device: &Device) -> Self {
        let init = ConvInit::TorchDefault;
        let guided = guidance_channels > 0;
        Self {
            convc1: conv2d([corr_channels, 64], 1, 1, 0, init, device),
            convc2: conv2d([64, 64], 3, 1, 1, init, device),
            convf1: conv2d([2, 64], 7, 1, 3, init, device),
            convf2: conv2d([64, 64], 3, 1, 1, init, device),
            convg1: guided.then(|| conv2d([guidance_channels, 64], 7, 1, 3, init, device)),
            convg2: guided.then(|| conv2d([64, 64], 3, 1, 1, init, device)),
            conv: conv2d([64 * (2 + guided as usize), 128 - 2], 3, 1, 1, init, device),
        }
    }

    /// The GRU input of one iteration: `[features, flow]` concatenated ([`Self::forward_parts`]).
    pub fn forward(&self, flow: Tensor<4>, corr: Tensor<4>, guidance: Option<&Tensor<4>>) -> Tensor<4> {
        Tensor::cat(Vec::from(self.forward_parts(flow, corr, guidance)), 1)
    }

    /// The GRU input of one iteration as its two parts, the 126 motion features and the flow
    /// (2 channels), not yet concatenated: the host GRU step copies its inputs into its own
    /// concatenation anyway, so building this one too was a wasted pass every iteration.
    ///
    /// # Shapes
    /// - `flow`: `[N, 2, H, W]`; `corr`: `[N, corr_channels, H, W]`; output `[N, 126, H, W]` and
    ///   `[N, 2, H, W]`
    pub fn forward_parts(&self, flow: Tensor<4>, corr: Tensor<4>, guidance: Option<&Tensor<4>>) -> [Tensor<4>; 2] {
        let cor = conv2d_relu_forward(&self.convc2, conv2d_relu_forward(&self.convc1, corr, UPDATE_LOOP), UPDATE_LOOP);
        let flo = conv2d_relu_forward(
            &self.convf2,
            conv2d_relu_forward(&self.convf1, flow.clone(), UPDATE_LOOP),
            UPDATE_LOOP,
        );
        let mut parts = vec![cor, flo];
        if let (Some(g1), Some(g2), Some(g)) = (&self.convg1, &self.convg2, guidance) {
            parts.push(conv2d_relu_forward(g2, conv2d_relu_forward(g1, g.clone(), UPDATE_LOOP), UPDATE_LOOP));
        }
        [conv2d_relu_forward(&self.conv, Tensor::cat(parts, 1), UPDATE_LOOP), flow]
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};
    use dgstereo_core::tensor::max_abs_diff;

    use super::*;

    /// The concatenated input is the two parts side by side, the flow passed through unchanged
    /// (with and without the guidance branch).
    #[test]
    fn forward_is_the_parts_concatenated() {
        let device = Device::flex();
        let rand = |c: usize| Tensor::<4>::random([2, c, 6, 7], Distribution::Normal(0.0, 1.0), &device);
        for guidance_channels in [0, 3] {
            let encoder = MotionEncoder::new(36, guidance_channels, &device);
            let (flow, corr, guidance) = (rand(2), rand(36), rand(guidance_channels.max(1)));
            let guidance = (guidance_channels > 0).then_some(&guidance);
            let [features, passed] = encoder.forward_parts(flow.clone(), corr.clone(), guidance);
            assert_eq!(features.dims(), [2, 126, 6, 7]);
            assert_eq!(max_abs_diff(passed, flow.clone()), 0.0);
            let whole = encoder.forward(flow.clone(), corr, guidance);
            assert_eq!(max_abs_diff(whole.clone().narrow(1, 0, 126), features), 0.0);
            assert_eq!(max_abs_diff(whole.narrow(1, 126, 2), flow), 0.0);
        }
    }
}
