//! Global-norm clipping (PyTorch's `clip_grad_norm_`) and frozen BatchNorm under AdamW.

use burn::module::{Module, Param};
use burn::nn::{Linear, LinearConfig};
use burn::optim::GradientsParams;
use burn::tensor::Tensor;
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_encoder::norm::FrozenBatchNorm;
use dgstereo_experiment::TrainingConfig;
use dgstereo_train::clip::{clip_global_norm, global_grad_norm};
use dgstereo_train::trainer::adamw;

#[derive(Module, Debug)]
struct Two {
    a: Linear,
    b: Linear,
}

/// A module and gradients equal to known coefficients: loss = sum(c_a * W_a) + sum(c_b * W_b) + ...
fn module_with_grads(scale: f32) -> (Two, GradientsParams, Vec<f32>) {
    let device = default_device().autodiff();
    let m = Two { a: LinearConfig::new(3, 2).init(&device), b: LinearConfig::new(2, 4).init(&device) };
    let mut all = Vec::new();
    let mut coeff = |n: usize| {
        let v: Vec<f32> = (0..n).map(|i| scale * ((i as f32 * 0.37).sin() + 0.1 * i as f32)).collect();
        all.extend_from_slice(&v);
        v
    };
    let ca = coeff(6);
    let cab = coeff(2);
    let cb = coeff(8);
    let cbb = coeff(4);
    let loss = (m.a.weight.val() * from_vec(ca, [3, 2], &device)).sum()
        + (m.a.bias.as_ref().unwrap().val() * from_vec(cab, [2], &device)).sum()
        + (m.b.weight.val() * from_vec(cb, [2, 4], &device)).sum()
        + (m.b.bias.as_ref().unwrap().val() * from_vec(cbb, [4], &device)).sum();
    let grads = GradientsParams::from_grads(loss.backward(), &m);
    (m, grads, all)
}

fn grads_of(m: &Two, g: &GradientsParams) -> Vec<f32> {
    let mut out = to_vec(g.get::<2>(m.a.weight.id).unwrap());
    out.extend(to_vec(g.get::<1>(m.a.bias.as_ref().unwrap().id).unwrap()));
    out.extend(to_vec(g.get::<2>(m.b.weight.id).unwrap()));
    out.extend(to_vec(g.get::<1>(m.b.bias.as_ref().unwrap().id).unwrap()));
    out
}

#[test]
fn global_norm_is_norm_over_all_parameters() {
    let (m, g, coeffs) = module_with_grads(1.0);
    let expect = coeffs.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
    let (norm, bad) = global_grad_norm(&m, &g);
    assert!(bad.is_none());
    assert!((norm - expect).abs() < 1e-5 * expect, "{norm} vs {expect}");
}

#[test]
fn clipping_scales_every_gradient_by_one_factor() {
    let (m, g, coeffs) = module_with_grads(3.0);
    let total = coeffs.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
    assert!(total > 1.0);
    let (g, report) = clip_global_norm(&m, g, 1.0);
    let coef = 1.0 / (total + 1e-6);
    assert!((report.scale - coef).abs() < 1e-6 * coef);
    let clipped = grads_of(&m, &g);
    for (c, k) in coeffs.iter().zip(&clipped) {
        assert!((f64::from(*c) * coef - f64::from(*k)).abs() < 1e-6, "{c} -> {k}");
    }
    let (after, _) = global_grad_norm(&m, &g);
    assert!((after - 1.0).abs() < 1e-4, "norm after clipping {after}");
}

#[test]
fn small_gradients_are_not_clipped() {
    let (m, g, coeffs) = module_with_grads(0.01);
    let (g, report) = clip_global_norm(&m, g, 1.0);
    assert_eq!(report.scale, 1.0);
    assert_eq!(grads_of(&m, &g), coeffs);
}

#[test]
fn non_finite_gradient_is_reported_with_its_parameter() {
    let device = default_device().autodiff();
    let m = Two { a: LinearConfig::new(3, 2).init(&device), b: LinearConfig::new(2, 4).init(&device) };
    let loss = m.a.weight.val().sum() + m.b.weight.val().sqrt().sum() * 0.0 + (m.b.weight.val() * f32::NAN).sum();
    let g = GradientsParams::from_grads(loss.backward(), &m);
    let (_, report) = clip_global_norm(&m, g, 1.0);
    assert_eq!(report.non_finite.as_deref(), Some("b.weight"));
    assert!(!report.total_norm.is_finite());
}

#[test]
fn frozen_batch_norm_statistics_never_update_while_affine_trains() {
    let plain = default_device();
    let device = plain.clone().autodiff();
    let mut bn = FrozenBatchNorm::new(4, &plain);
    bn.running_mean = Param::from_tensor(from_vec(vec![0.5, -1.0, 2.0, 0.0], [4], &plain)).set_require_grad(false);
    bn.running_var = Param::from_tensor(from_vec(vec![2.0, 0.5, 1.0, 3.0], [4], &plain)).set_require_grad(false);
    let mut bn = bn.fork(&device).train();
    let (mean0, var0) = (to_vec(bn.running_mean.val()), to_vec(bn.running_var.val()));
    let (w0, b0) = (to_vec(bn.weight.val()), to_vec(bn.bias.val()));
    let mut optimizer = adamw(&TrainingConfig { weight_decay: 0.1, ..TrainingConfig::default() });
    for k in 0..3 {
        // A batch whose statistics differ from the running ones: training-mode BN would move them.
        let x: Tensor<4> =
            from_vec((0..4 * 4 * 9).map(|i| ((i * 7 + k) % 11) as f32 * 3.0 + 5.0).collect(), [4, 4, 3, 3], &device);
        let y = bn.forward(x);
        let loss = (y.clone() * y).mean();
        let grads = GradientsParams::from_grads(loss.backward(), &bn);
        assert!(grads.get::<1>(bn.running_mean.id).is_none() && grads.get::<1>(bn.running_var.id).is_none());
        bn = optimizer.step(1e-2, bn, grads);
    }
    assert_eq!(to_vec(bn.running_mean.val()), mean0, "running mean changed");
    assert_eq!(to_vec(bn.running_var.val()), var0, "running variance changed");
    assert_ne!(to_vec(bn.weight.val()), w0, "the scale must train");
    assert_ne!(to_vec(bn.bias.val()), b0, "the shift must train");
}
