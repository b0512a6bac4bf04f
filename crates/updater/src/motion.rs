//! The motion encoder: correlation, current disparity and (optionally) depth guidance merged
//! into the GRU's input.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::host_conv::conv2d_relu_forward;
use dgstereo_core::layers::{ConvInit, conv2d};

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

    /// The GRU input of one iteration.
    pub fn forward(&self, flow: Tensor<4>, corr: Tensor<4>, guidance: Option<&Tensor<4>>) -> Tensor<4> {
        let cor = conv2d_relu_forward(&self.convc2, conv2d_relu_forward(&self.convc1, corr));
        let flo = conv2d_relu_forward(&self.convf2, conv2d_relu_forward(&self.convf1, flow.clone()));
        let mut parts = vec![cor, flo];
        if let (Some(g1), Some(g2), Some(g)) = (&self.convg1, &self.convg2, guidance) {
            parts.push(conv2d_relu_forward(g2, conv2d_relu_forward(g1, g.clone())));
        }
        let out = conv2d_relu_forward(&self.conv, Tensor::cat(parts, 1));
        Tensor::cat(vec![out, flow], 1)
    }
}
