//! The motion encoder: correlation, current disparity and (optionally) depth guidance merged
//! into the GRU's input.
//!
//! The disparity enters as RAFT-Stereo's two-channel flow (`x`, `y = 0`; `convf1`, `convf2`) or
//! as DEFOM-Stereo's (and IGEV-Stereo's) one-channel positive disparity (`convd1`, `convd2`),
//! [`MotionKind`]; either is appended to the features, which fill the rest of 128 channels.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::conv2d_relu_forward;
use serde::{Deserialize, Serialize};

use crate::loop_numerics::UPDATE_LOOP;

/// What the update loop iterates, which the motion encoder reads and the head predicts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum MotionKind {
    /// RAFT-Stereo's x flow (negative disparity), read as two channels `(x, 0)`; its head
    /// (`flow_head`) predicts two, of which `x` is kept.
    #[default]
    Flow,
    /// A positive disparity, one channel; its head (`disp_head`) predicts one (DEFOM-Stereo,
    /// IGEV-Stereo).
    Disparity,
}

impl MotionKind {
    /// Every kind, in the order of the enum.
    pub const ALL: [Self; 2] = [Self::Flow, Self::Disparity];

    /// The name the TOML key `motion` writes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Flow => "flow",
            Self::Disparity => "disparity",
        }
    }

    /// Channels of the motion input and of the head's output.
    pub fn channels(self) -> usize {
        match self {
            Self::Flow => 2,
            Self::Disparity => 1,
        }
    }
}

/// Correlation branch (1x1, 3x3), flow or disparity branch (7x7, 3x3) and an optional guidance
/// branch (7x7, 3x3) joined by a 3x3 merge convolution; the motion input (2-channel flow or
/// 1-channel disparity, [`MotionKind`]) is appended to the output.
///
/// # Shapes
/// - `corr`: `[N, corr_channels, H, W]`, `flow`: `[N, m, H, W]`, `guidance`: `[N, g, H, W]`
/// - output: `[N, 128, H, W]`
#[derive(Module, Debug)]
pub struct MotionEncoder {
    /// 1x1 on the correlation.
    pub convc1: Conv2d,
    /// 3x3 on the correlation branch.
    pub convc2: Conv2d,
    /// 7x7 on the flow (RAFT-Stereo).
    pub convf1: Option<Conv2d>,
    /// 3x3 on the flow branch.
    pub convf2: Option<Conv2d>,
    /// 7x7 on the disparity (DEFOM-Stereo's `convd1`).
    pub convd1: Option<Conv2d>,
    /// 3x3 on the disparity branch.
    pub convd2: Option<Conv2d>,
    /// 7x7 on the guidance (the paper's Gradient-GRU); absent in RAFT-Stereo.
    pub convg1: Option<Conv2d>,
    /// 3x3 on the guidance branch.
    pub convg2: Option<Conv2d>,
    /// Merge convolution to `128 - m` channels.
    pub conv: Conv2d,
}

impl MotionEncoder {
    /// The encoder for `corr_channels` correlation channels, the motion input `motion` and
    /// `guidance_channels` (0 = none).
    pub fn new(corr_channels: usize, motion: MotionKind, guidance_channels: usize, device: &Device) -> Self {
        let init = ConvInit::TorchDefault;
        let guided = guidance_channels > 0;
        let m = motion.channels();
        let branch = |kind: MotionKind, kernel: usize, cin: usize| {
            (motion == kind).then(|| conv2d([cin, 64], kernel, 1, kernel / 2, init, device))
        };
        Self {
            convc1: conv2d([corr_channels, 64], 1, 1, 0, init, device),
            convc2: conv2d([64, 64], 3, 1, 1, init, device),
            convf1: branch(MotionKind::Flow, 7, m),
            convf2: branch(MotionKind::Flow, 3, 64),
            convd1: branch(MotionKind::Disparity, 7, m),
            convd2: branch(MotionKind::Disparity, 3, 64),
            convg1: guided.then(|| conv2d([guidance_channels, 64], 7, 1, 3, init, device)),
            convg2: guided.then(|| conv2d([64, 64], 3, 1, 1, init, device)),
            conv: conv2d([64 * (2 + guided as usize), 128 - m], 3, 1, 1, init, device),
        }
    }

    /// The GRU input of one iteration: `[features, flow]` concatenated ([`Self::forward_parts`]).
    pub fn forward(&self, flow: Tensor<4>, corr: Tensor<4>, guidance: Option<&Tensor<4>>) -> Tensor<4> {
        Tensor::cat(Vec::from(self.forward_parts(flow, corr, guidance)), 1)
    }

    /// The GRU input of one iteration as its two parts, the `128 - m` motion features and the
    /// motion input (`m` channels), not yet concatenated: the host GRU step copies its inputs into
    /// its own concatenation anyway, so building this one too was a wasted pass every iteration.
    ///
    /// # Shapes
    /// - `flow`: `[N, m, H, W]`; `corr`: `[N, corr_channels, H, W]`; output `[N, 128 - m, H, W]`
    ///   and `[N, m, H, W]`
    pub fn forward_parts(&self, flow: Tensor<4>, corr: Tensor<4>, guidance: Option<&Tensor<4>>) -> [Tensor<4>; 2] {
        let cor = conv2d_relu_forward(&self.convc2, conv2d_relu_forward(&self.convc1, corr, UPDATE_LOOP), UPDATE_LOOP);
        let (first, second) = [(&self.convf1, &self.convf2), (&self.convd1, &self.convd2)]
            .into_iter()
            .find_map(|(c1, c2)| c1.as_ref().zip(c2.as_ref()))
            .expect("the constructor builds a flow or a disparity branch");
        let flo = conv2d_relu_forward(second, conv2d_relu_forward(first, flow.clone(), UPDATE_LOOP), UPDATE_LOOP);
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
            let encoder = MotionEncoder::new(36, MotionKind::Flow, guidance_channels, &device);
            let (flow, corr, guidance) = (rand(2), rand(36), rand(guidance_channels.max(1)));
            let guidance = (guidance_channels > 0).then_some(&guidance);
            let [features, passed] = encoder.forward_parts(flow.clone(), corr.clone(), guidance);
            assert_eq!(features.dims(), [2, 126, 6, 7]);
            assert_eq!(max_abs_diff(passed, flow.clone()), 0.0);
            let whole = encoder.forward(flow.clone(), corr, guidance);
            assert_eq!(max_abs_diff(whole.clone().narrow(1, 0, 126), features), 0.0);
            assert_eq!(max_abs_diff(whole.narrow(1, 126, 2), flow), 0.0);
        }
        // The disparity input: one channel, appended to 127 features, through `convd1`/`convd2`.
        let encoder = MotionEncoder::new(40, MotionKind::Disparity, 0, &device);
        assert!(encoder.convf1.is_none() && encoder.convd1.as_ref().map(|c| c.weight.dims()) == Some([64, 1, 7, 7]));
        let disparity = rand(1);
        let [features, passed] = encoder.forward_parts(disparity.clone(), rand(40), None);
        assert_eq!(features.dims(), [2, 127, 6, 7]);
        assert_eq!(max_abs_diff(passed, disparity), 0.0);
    }

    /// `MotionKind::ALL` lists every kind serde accepts, once, in the enum's order, named as
    /// TOML writes it.
    #[test]
    fn every_motion_kind_is_listed() {
        use serde::Deserialize;
        use serde::de::value::{Error, StrDeserializer};
        let accepted = dgstereo_core::serde_names::accepted_names::<MotionKind>().unwrap();
        let listed: Vec<&str> = MotionKind::ALL.iter().map(|k| k.name()).collect();
        assert_eq!(listed, accepted);
        for kind in MotionKind::ALL {
            assert_eq!(MotionKind::deserialize(StrDeserializer::<Error>::new(kind.name())), Ok(kind));
        }
    }
}
