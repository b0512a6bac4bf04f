//! The frozen batch norm every stage with PyTorch `BatchNorm2d` layers loads official weights into.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor};

const EPS: f64 = 1e-5;

/// BatchNorm in evaluation mode at all times (RAFT-Stereo's `freeze_bn`; IGEV-Stereo's networks
/// run in evaluation mode).
///
/// The running statistics never update; `weight` and `bias` still train. Fields carry PyTorch's
/// names so official checkpoints load without renaming.
#[derive(Module, Debug)]
pub struct FrozenBatchNorm {
    /// Scale (`gamma`).
    pub weight: Param<Tensor<1>>,
    /// Shift (`beta`).
    pub bias: Param<Tensor<1>>,
    /// Running mean; not trained.
    pub running_mean: Param<Tensor<1>>,
    /// Running variance; not trained.
    pub running_var: Param<Tensor<1>>,
    /// Added to the variance.
    pub epsilon: f64,
}

impl FrozenBatchNorm {
    /// A fresh layer: identity statistics, unit scale, zero shift.
    pub fn new(channels: usize, device: &Device) -> Self {
        let frozen = |t: Tensor<1>| Param::from_tensor(t).set_require_grad(false);
        Self {
            weight: Param::from_tensor(Tensor::ones([channels], device)),
            bias: Param::from_tensor(Tensor::zeros([channels], device)),
            running_mean: frozen(Tensor::zeros([channels], device)),
            running_var: frozen(Tensor::ones([channels], device)),
            epsilon: EPS,
        }
    }

    /// The per-channel affine the layer applies: `(weight / sqrt(var + eps), bias - mean · scale)`.
    ///
    /// # Shapes
    /// - both `[C]`
    pub fn scale_shift(&self) -> (Tensor<1>, Tensor<1>) {
        let scale = self.weight.val() / self.running_var.val().detach().add_scalar(self.epsilon).sqrt();
        let shift = self.bias.val() - self.running_mean.val().detach() * scale.clone();
        (scale, shift)
    }

    /// Normalises `[N, C, ...]` (a 2D map or a 3D volume) with the running statistics, per
    /// channel (dimension 1).
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        let mut shape = [1; D];
        shape[1] = self.weight.dims()[0];
        let (scale, shift) = self.scale_shift();
        x * scale.reshape(shape) + shift.reshape(shape)
    }
}
