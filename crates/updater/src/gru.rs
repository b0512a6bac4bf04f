//! The convolutional GRU cell.
//!
//! The update and reset gates read the same input `[h, x]`, so one step runs them as a single
//! convolution with `2·hidden` output channels: the weights of `convz` and `convr` are
//! concatenated at each call (a few MB, next to a multi-GMAC convolution), which halves the
//! im2col work and gives the matrix product a wider output. The modules stay separate so the
//! official checkpoint keys `convz`, `convr`, `convq` keep loading and training updates each.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor};
use dgstereo_core::layers::{ConvInit, conv2d};
use dgstereo_kernels::gpu::matmul_conv::{SharedColumns, shared_columns_apply};
use dgstereo_kernels::{
    conv_gru_step_or, conv_options, conv2d_forward_then, conv2d_op_then, flat_pixels, gru_blend, gru_gates,
};

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

    /// One step: the kernels' fused host step for CPU inference, [`Self::tensor_step`]
    /// elsewhere.
    pub fn forward(&self, h: Tensor<4>, ctx: &GateContext, inputs: Vec<Tensor<4>>) -> Tensor<4> {
        let convs = [&self.convz, &self.convr, &self.convq];
        conv_gru_step_or(convs, h, [&ctx.zr, &ctx.q], &inputs, |h| self.tensor_step(h, ctx, &inputs))
    }

    /// One step of burn's tensor operations (the reference, and the training path).
    fn tensor_step(&self, h: Tensor<4>, ctx: &GateContext, inputs: &[Tensor<4>]) -> Tensor<4> {
        let hidden = h.dims()[1];
        // `[h, x]` and `[r·h, x]` each as one concatenation of all parts (no `x` of its own: one
        // copy fewer a step).
        let with_inputs =
            |first: Tensor<4>| Tensor::cat([first].into_iter().chain(inputs.iter().cloned()).collect(), 1);
        // The gates' context, the activations and the blend are each convolution's epilogue, on
        // `[N, C, H·W]` with their operands flattened before it (GPU inference runs them in the
        // product's kernel: `conv2d_op_then`). On the GPU the inputs' columns are gathered once
        // for both convolutions (`SharedColumns`).
        let shared = self.shared_columns(inputs);
        let zr_context = flat_pixels(ctx.zr.clone());
        let gates = |zr: Tensor<3>| gru_gates(zr, zr_context);
        let zr = match &shared {
            Some(shared) => {
                let (weight, bias) = self.gate_weights();
                shared.conv_then(h.clone(), weight, bias, gates)
            }
            None => self.gates_then(with_inputs(h.clone()), gates),
        };
        let z = flat_pixels(zr.clone().narrow(1, 0, hidden));
        let r = zr.narrow(1, hidden, hidden);
        let (h_flat, q_context) = (flat_pixels(h.clone()), flat_pixels(ctx.q.clone()));
        let blend = |q: Tensor<3>| gru_blend(q, q_context, z, h_flat);
        match shared {
            Some(shared) => {
                let bias = self.convq.bias.as_ref().map(|b| b.val());
                shared.conv_then(r * h, self.convq.weight.val(), bias, blend)
            }
            None => conv2d_forward_then(&self.convq, with_inputs(r * h), blend),
        }
    }

    /// The inputs' columns for both convolutions of a step, where GPU inference shares them
    /// (`shared_columns_apply`) and the candidate's convolution has the gates' geometry.
    fn shared_columns(&self, inputs: &[Tensor<4>]) -> Option<SharedColumns> {
        let options = self.gate_options();
        let [_, _, kh, kw] = self.convz.weight.dims();
        let device = inputs.first()?.device();
        if !shared_columns_apply(&device, &options, [kh, kw]) || conv_options(&self.convq) != Some(options.clone()) {
            return None;
        }
        let x = if inputs.len() == 1 { inputs[0].clone() } else { Tensor::cat(inputs.to_vec(), 1) };
        Some(SharedColumns::gather(x, [kh, kw], &options))
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
        self.gates_then(hx, |zr| zr)
    }

    /// [`Self::gates`] followed by `then` on its output seen as `[N, 2·hidden, H·W]`
    /// (`conv2d_op_then`).
    fn gates_then(&self, hx: Tensor<4>, then: impl FnOnce(Tensor<3>) -> Tensor<3>) -> Tensor<4> {
        let (weight, bias) = self.gate_weights();
        conv2d_op_then(hx, weight, bias, self.gate_options(), then)
    }

    /// The weights and biases of `convz` and `convr` stacked along the output channels: the one
    /// convolution of both gates.
    ///
    /// # Shapes
    /// - weight `[2·hidden, hidden + input_dim, kh, kw]`; bias `[2·hidden]`
    pub(crate) fn gate_weights(&self) -> (Tensor<4>, Option<Tensor<1>>) {
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
