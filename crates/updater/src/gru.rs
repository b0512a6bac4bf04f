//! The convolutional GRU cell.
//!
//! The step is one operation of the kernels crate (`conv_gru_step`), which runs the update and
//! reset gates as a single convolution of the concatenated weights and arranges the rest for the
//! path it takes. The modules stay separate so the official checkpoint keys `convz`, `convr`,
//! `convq` keep loading and training updates each.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::{conv_gru_step, conv2d_op};

use crate::loop_numerics::UPDATE_LOOP;

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
    /// `z` and `r` stacked along channels (`[N, 2·hidden, H, W]`), added to the fused gates.
    pub zr: Tensor<4>,
}

impl GateContext {
    /// Splits the output of a level's context convolution, `[N, 3·hidden, H, W]` ordered
    /// `z, r, q` along channels (the reference's `context_zqr_convs`).
    pub fn from_zqr(zqr: Tensor<4>) -> Self {
        let d = zqr.dims()[1] / 3;
        Self {
            z: zqr.clone().narrow(1, 0, d),
            r: zqr.clone().narrow(1, d, d),
            zr: zqr.clone().narrow(1, 0, 2 * d),
            q: zqr.narrow(1, 2 * d, d),
        }
    }
}

impl ConvGru {
    /// A cell with `hidden` state channels and `input_dim` input channels, 3x3 kernels.
    pub fn new(hidden: usize, input_dim: usize, device: &Device) -> Self {
        let c = |_| conv2d([hidden + input_dim, hidden], 3, 1, 1, ConvInit::TorchDefault, device);
        Self { convz: c(0), convr: c(1), convq: c(2) }
    }

    /// One step, as the kernels crate's `conv_gru_step` runs it on this device (the numerics of
    /// the update loop: nothing after it magnifies a change of rounding).
    pub fn forward(&self, h: Tensor<4>, ctx: &GateContext, inputs: Vec<Tensor<4>>) -> Tensor<4> {
        let convs = [&self.convz, &self.convr, &self.convq];
        conv_gru_step(convs, h, [&ctx.zr, &ctx.q], &inputs, UPDATE_LOOP)
    }

    /// The gates' convolution options: `convz`'s, padded to keep the size.
    fn gate_options(&self) -> ConvOptions<2> {
        let [_, _, kh, kw] = self.convz.weight.dims();
        ConvOptions::new(self.convz.stride, [kh / 2, kw / 2], self.convz.dilation, self.convz.groups)
    }

    /// `[convz(hx), convr(hx)]` as one convolution of the concatenated weights.
    ///
    /// # Shapes
    /// - `hx`: `[N, hidden + input_dim, H, W]`; output `[N, 2·hidden, H, W]`
    pub fn gates(&self, hx: Tensor<4>) -> Tensor<4> {
        let (weight, bias) = self.gate_weights();
        conv2d_op(hx, weight, bias, self.gate_options(), UPDATE_LOOP)
    }

    /// The weights and biases of `convz` and `convr` stacked along the output channels: the one
    /// convolution of both gates.
    ///
    /// # Shapes
    /// - weight `[2·hidden, hidden + input_dim, kh, kw]`; bias `[2·hidden]`
    fn gate_weights(&self) -> (Tensor<4>, Option<Tensor<1>>) {
        let weight = Tensor::cat(vec![self.convz.weight.val(), self.convr.weight.val()], 0);
        let bias = match (&self.convz.bias, &self.convr.bias) {
            (Some(bz), Some(br)) => Some(Tensor::cat(vec![bz.val(), br.val()], 0)),
            _ => None,
        };
        (weight, bias)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::activation::{sigmoid, tanh};

    use super::*;
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::max_abs_diff;

    /// The fused gate convolution equals the two separate ones, and the step equals the
    /// reference formula written with them.
    #[test]
    fn fused_gates_equal_separate_convolutions() {
        let device = default_device();
        let gru = ConvGru::new(8, 6, &device);
        let rand = |c: usize| Tensor::<4>::random([2, c, 5, 7], Distribution::Normal(0.0, 1.0), &device);
        let (h, x) = (rand(8), rand(6));
        let ctx = GateContext::from_zqr(rand(24));
        let hx = Tensor::cat(vec![h.clone(), x.clone()], 1);
        let fused = gru.gates(hx.clone());
        let separate = Tensor::cat(vec![gru.convz.forward(hx.clone()), gru.convr.forward(hx.clone())], 1);
        assert!(max_abs_diff(fused, separate) < 1e-5);
        let z = sigmoid(gru.convz.forward(hx.clone()) + ctx.z.clone());
        let r = sigmoid(gru.convr.forward(hx) + ctx.r.clone());
        let q = tanh(gru.convq.forward(Tensor::cat(vec![r * h.clone(), x.clone()], 1)) + ctx.q.clone());
        let expected = (z.clone().neg().add_scalar(1.0)) * h.clone() + z * q;
        assert!(max_abs_diff(gru.forward(h, &ctx, vec![x]), expected) < 1e-5);
    }

    /// The fused host step (CPU inference) equals the tensor-op step (run on the autodiff
    /// device, where the fused step never applies and only the gates and blend are host nodes);
    /// returns the largest difference.
    fn host_and_tensor_steps_differ_by(n: usize, hidden: usize, inputs: [usize; 2], [h, w]: [usize; 2]) -> f32 {
        use burn::module::Module;
        let device = default_device();
        let ad = device.clone().autodiff();
        let gru = ConvGru::new(hidden, inputs[0] + inputs[1], &device);
        let gru_ad = gru.clone().fork(&ad);
        use dgstereo_kernels::{Op, Path, path};
        assert!(path(&device, Op::GruStep) == Path::Host, "CPU inference takes the fused step");
        let rand = |c: usize| Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let (hidden_state, x1, x2, zqr) = (rand(hidden), rand(inputs[0]), rand(inputs[1]), rand(3 * hidden));
        let on_ad = |t: &Tensor<4>| Tensor::<4>::from_data(t.to_data(), &ad);
        let host = gru.forward(hidden_state.clone(), &GateContext::from_zqr(zqr.clone()), vec![x1.clone(), x2.clone()]);
        let stock =
            gru_ad.forward(on_ad(&hidden_state), &GateContext::from_zqr(on_ad(&zqr)), vec![on_ad(&x1), on_ad(&x2)]);
        max_abs_diff(host, Tensor::from_data(stock.into_data(), &device))
    }

    /// Few channels (the im2col path), several inputs and a batch of two.
    #[test]
    fn host_step_equals_the_tensor_step() {
        let diff = host_and_tensor_steps_differ_by(2, 16, [5, 7], [9, 13]);
        assert!(diff < 1e-5, "{diff}");
    }

    /// The GRUs' channel counts scaled down but past the Winograd thresholds, on a grid for
    /// F(2x2) and one for F(4x4): the candidate's x channels are transformed once, by the gates'
    /// convolution (`conv2d_host_shared_first`).
    #[test]
    fn host_step_with_shared_transforms_equals_the_tensor_step() {
        for size in [[20, 26], [44, 48]] {
            let diff = host_and_tensor_steps_differ_by(1, 32, [24, 24], size);
            assert!(diff < 1e-4, "{size:?}: {diff}");
        }
    }
}
