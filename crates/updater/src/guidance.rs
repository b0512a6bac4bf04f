//! Depth guidance of the GRU: the paper's gradient feature and its ablation variants.

use burn::tensor::module::conv2d;
use burn::tensor::ops::{ConvOptions, PadMode};
use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::instance_norm;
use dgstereo_kernels::resize_bilinear;
use serde::{Deserialize, Serialize};

const EPS: f64 = 1e-6;
const IN_EPS: f64 = 1e-5;

/// What the GRU's guidance branch sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum GuidanceKind {
    /// No guidance branch (RAFT-Stereo).
    #[default]
    None,
    /// Direction and magnitude of the depth gradient (3 channels; the paper's Gradient-GRU).
    Gradient,
    /// The instance-normalised depth itself (1 channel; the paper's "depth-guided GRU").
    Depth,
}

impl GuidanceKind {
    /// Every kind, in the order of the enum. Tests and the experiment crate's checks draw the
    /// kinds from here, so a new kind is listed once, in this crate (`every_kind_is_listed` in
    /// the tests fails otherwise).
    pub const ALL: [Self; 3] = [Self::None, Self::Gradient, Self::Depth];

    /// The kind's name as the TOML key `guidance` writes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Gradient => "gradient",
            Self::Depth => "depth",
        }
    }

    /// Channels of the guidance feature (0 for none).
    pub fn channels(self) -> usize {
        match self {
            Self::None => 0,
            Self::Gradient => 3,
            Self::Depth => 1,
        }
    }

    /// The guidance feature of a left depth prior at the update grid `[h, w]`; computed once per
    /// pair. `None` when this kind has no branch.
    ///
    /// # Shapes
    /// - `depth`: `[N, 1, H, W]`; output `[N, channels, h, w]`
    pub fn feature(self, depth: Tensor<4>, grid: [usize; 2]) -> Option<Tensor<4>> {
        match self {
            Self::None => None,
            Self::Depth => Some(instance_norm(resize_bilinear(depth, grid, false), IN_EPS)),
            Self::Gradient => Some(gradient_feature(depth, grid)),
        }
    }
}

/// The paper's gradient feature.
///
/// The depth is resized bilinearly to the grid, instance-normalised, and differentiated by 3x3
/// Sobel filters with replicate padding; with `M = sqrt(Gx² + Gy² + ε)` the channels are
/// `Gx/(M+ε)`, `Gy/(M+ε)` and `IN(M)`, `ε = 1e-6`. Instance normalisation first makes the
/// feature invariant to positive affine changes of the depth.
///
/// # Shapes
/// - `depth`: `[N, 1, H, W]`; output `[N, 3, h, w]`
pub fn gradient_feature(depth: Tensor<4>, grid: [usize; 2]) -> Tensor<4> {
    let device = depth.device();
    let d = instance_norm(resize_bilinear(depth, grid, false), IN_EPS);
    let padded = d.pad([(0, 0), (0, 0), (1, 1), (1, 1)], PadMode::Edge);
    #[rustfmt::skip]
    let sobel = TensorData::new(vec![
        -1.0f32, 0.0, 1.0, -2.0, 0.0, 2.0, -1.0, 0.0, 1.0,
        -1.0, -2.0, -1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 1.0,
    ], [2, 1, 3, 3]);
    let weight = Tensor::<4>::from_data(sobel, &device);
    let g = conv2d(padded, weight, None, ConvOptions::new([1, 1], [0, 0], [1, 1], 1));
    let [n, _, h, w] = g.dims();
    let gx = g.clone().slice([0..n, 0..1, 0..h, 0..w]);
    let gy = g.slice([0..n, 1..2, 0..h, 0..w]);
    let m = (gx.clone().square() + gy.clone().square()).add_scalar(EPS).sqrt();
    let denom = m.clone().add_scalar(EPS);
    Tensor::cat(vec![gx / denom.clone(), gy / denom, instance_norm(m, IN_EPS)], 1)
}
