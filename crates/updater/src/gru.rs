//! The convolutional GRU cell.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor, activation::{sigmoid, tanh}};
use dgstereo_core::layers::{ConvInit, conv2d};

/// A ConvGRU whose gates also receive precomputed context terms.
///
/// `z = σ(convz([h,x]) + cz)`, `r = σ(convr([h,x]) + cr)`, `q = tanh(convq([r·h, x]) + cq)`,
/// `h' = (1 - z)·h + z·q`, with `x` the concatenation of the inputs.
///
/// # Shapes
/// - `h`, `cz`, `cr`, `cq`: `[N, hidden, H, W]`; inputs `[N, *, H, W]` adding to `input_dim`
#[derive(Module, Debug)]
pub struct ConvGru {
    /// Update gate.
    pub convz: Conv2d,
    /// Reset gate.
    pub convr: Conv2d,
    /// Candidate state.
    pub convq: Conv2d,
}

/// The context terms of one GRU level (`cz`, `cr`, `cq`).
#[derive(Debug, Clone)]
pub struct GateContext {
    /// Added to the update gate.
    pub z: Tensor<4>,
    /// Added to the reset gate.
    pub r: Tensor<4>,
    /// Added to the candidate.
    pub q: Tensor<4>,
}

impl ConvGru {
    /// A cell with `hidden` state channels and `input_dim` input channels, 3x3 kernels.
    pub fn new(hidden: usize, input_dim: usize, device: &Device) -> Self {
        let c = |_| conv2d([hidden + input_dim, hidden], 3, 1, 1, ConvInit::TorchDefault, device);
        Self { convz: c(0), convr: c(1), convq: c(2) }
    }

    /// One step.
    pub fn forward(&self, h: Tensor<4>, ctx: &GateContext, inputs: Vec<Tensor<4>>) -> Tensor<4> {
        let x = Tensor::cat(inputs, 1);
        let hx = Tensor::cat(vec![h.clone(), x.clone()], 1);
        let z = sigmoid(self.convz.forward(hx.clone()) + ctx.z.clone());
        let r = sigmoid(self.convr.forward(hx) + ctx.r.clone());
        let q = tanh(self.convq.forward(Tensor::cat(vec![r * h.clone(), x], 1)) + ctx.q.clone());
        (z.clone().neg().add_scalar(1.0)) * h + z * q
    }
}
