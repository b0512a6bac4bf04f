//! Global-norm gradient clipping over all parameters, as PyTorch's `clip_grad_norm_`.
//!
//! burn's own clipping acts per parameter; RAFT-Stereo clips the norm of the concatenation of
//! every gradient: `total = sqrt(sum_p ||g_p||²)`, and when `total > max_norm` every gradient is
//! multiplied by `max_norm / (total + 1e-6)`. The total norm is also the run's test for NaN or inf
//! in the gradients: a non-finite norm is reported with the first parameter at fault.

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::Tensor;

/// What clipping found.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipReport {
    /// The global norm before clipping.
    pub total_norm: f64,
    /// The factor applied to every gradient (1 when no clipping happened).
    pub scale: f64,
    /// The first parameter (module path) whose gradient holds NaN or inf, if any.
    pub non_finite: Option<String>,
}

struct SquaredNorms<'a> {
    grads: &'a GradientsParams,
    path: Vec<String>,
    norms: Vec<(String, Tensor<1>)>,
}

impl ModuleVisitor for SquaredNorms<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            self.norms.push((self.path.join("."), g.square().sum()));
        }
    }
}

struct Scaler<'a> {
    grads: &'a mut GradientsParams,
    scale: f64,
}

impl ModuleVisitor for Scaler<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let id: ParamId = param.id;
        if let Some(g) = self.grads.remove::<D>(id) {
            self.grads.register::<D>(id, g.mul_scalar(self.scale));
        }
    }
}

/// The global L2 norm of `grads` over the parameters of `module`, and the first parameter
/// whose gradient is not finite.
pub fn global_grad_norm<M: Module>(module: &M, grads: &GradientsParams) -> (f64, Option<String>) {
    let mut visitor = SquaredNorms { grads, path: Vec::new(), norms: Vec::new() };
    module.visit(&mut visitor);
    if visitor.norms.is_empty() {
        return (0.0, None);
    }
    let (names, sums): (Vec<String>, Vec<Tensor<1>>) = visitor.norms.into_iter().unzip();
    let sums = dgstereo_core::tensor::to_vec(Tensor::cat(sums, 0));
    let non_finite = sums.iter().position(|s| !s.is_finite()).map(|i| names[i].clone());
    let total = sums.iter().map(|&s| f64::from(s)).sum::<f64>().sqrt();
    (total, non_finite)
}

/// Clips `grads` to a global norm of `max_norm` (PyTorch's `clip_grad_norm_`); `max_norm <= 0`
/// only measures. Non-finite gradients are left as they are and reported.
pub fn clip_global_norm<M: Module>(
    module: &M,
    mut grads: GradientsParams,
    max_norm: f64,
) -> (GradientsParams, ClipReport) {
    let (total_norm, non_finite) = global_grad_norm(module, &grads);
    let mut scale = 1.0;
    if non_finite.is_none() && max_norm > 0.0 {
        let coef = max_norm / (total_norm + 1e-6);
        if coef < 1.0 {
            scale = coef;
            module.visit(&mut Scaler { grads: &mut grads, scale });
        }
    }
    (grads, ClipReport { total_norm, scale, non_finite })
}
