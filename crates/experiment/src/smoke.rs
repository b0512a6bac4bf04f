//! The smoke test of a run: build its model, count its parameters, run a tiny forward pass.
//!
//! This is what `dgstereo experiment check` does for every resolved run. The pair is synthetic
//! (a textured plane shifted by a few pixels) and the depth prior, when the model takes one, is
//! a simple ramp: the point is that the configuration builds and runs, not what it predicts, so
//! neither the prior provider nor its weights are needed.

use std::panic::{AssertUnwindSafe, catch_unwind};

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Tensor};
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_core::{DepthPrior, Error, Result};
use dgstereo_model::StereoModel;

use crate::ExperimentConfig;

/// What [`smoke_test`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct SmokeReport {
    /// Trainable parameters of the model (frozen BatchNorm statistics excluded).
    pub parameters: usize,
    /// Disparity maps returned (one per iteration).
    pub iterations: usize,
    /// Largest |disparity| of the last map.
    pub max_abs_disparity: f32,
}

impl SmokeReport {
    /// The parameter count as people write it: `11,116,176 (11.12 M)`.
    pub fn parameters_text(&self) -> String {
        let digits = self.parameters.to_string();
        let mut grouped = String::new();
        for (i, c) in digits.chars().enumerate() {
            if i > 0 && (digits.len() - i).is_multiple_of(3) {
                grouped.push(',');
            }
            grouped.push(c);
        }
        format!("{grouped} ({:.2} M)", self.parameters as f64 / 1e6)
    }
}

/// Counts the trainable parameters of a module: every float parameter except frozen BatchNorm
/// statistics (`running_mean`, `running_var`), which is how the reference counts RAFT-Stereo's
/// 11.12 M.
pub fn trainable_parameters<M: Module>(module: &M) -> usize {
    #[derive(Default)]
    struct Counter {
        path: Vec<String>,
        total: usize,
    }
    impl ModuleVisitor for Counter {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let frozen = matches!(self.path.last().map(String::as_str), Some("running_mean" | "running_var"));
            if !frozen {
                self.total += param.shape().num_elements();
            }
        }
    }
    let mut counter = Counter::default();
    module.visit(&mut counter);
    counter.total
}

/// A textured `[1, 3, h, w]` pair whose right view is the left shifted by `shift` pixels, and a
/// prior ramp per view.
///
/// # Shapes
/// - images `[1, 3, h, w]` in 0..255; prior maps `[1, 1, h, w]`
pub fn synthetic_pair(size: [usize; 2], shift: usize, device: &Device) -> (Tensor<4>, Tensor<4>, DepthPrior) {
    let [h, w] = size;
    let texture = |x: f32, y: f32, c: usize| {
        let v = (0.37 * x + 0.11 * c as f32).sin() * (0.23 * y + 0.7).cos() + (0.05 * x * y + c as f32).sin() * 0.5;
        127.5 + 80.0 * v
    };
    let image = |offset: f32| {
        let mut values = Vec::with_capacity(3 * h * w);
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    values.push(texture(x as f32 + offset, y as f32, c));
                }
            }
        }
        from_vec(values, [1, 3, h, w], device)
    };
    let ramp: Vec<f32> =
        (0..h).flat_map(|y| (0..w).map(move |x| 1.0 + (y as f32) / h as f32 + 0.2 * (x as f32) / w as f32)).collect();
    let prior = from_vec(ramp, [1, 1, h, w], device);
    (image(0.0), image(shift as f32), DepthPrior { left: prior.clone(), right: prior })
}

/// Builds the model of `config`, counts its parameters and runs `iters` iterations on a
/// synthetic `size` pair (with a synthetic prior when the model takes one).
///
/// # Errors
/// The configuration is invalid, the model cannot be built, the forward pass fails or panics,
/// or a disparity map has the wrong size or non-finite values.
pub fn smoke_test(config: &ExperimentConfig, size: [usize; 2], iters: usize, device: &Device) -> Result<SmokeReport> {
    config.validate()?;
    let run = || -> Result<SmokeReport> {
        let network = config.model.init(device)?;
        let parameters = trainable_parameters(&network);
        let model = StereoModel::new(network, config.model.clone(), device.clone());
        let (left, right, prior) = synthetic_pair(size, 3, device);
        let prior = config.model.needs_prior().then_some(prior);
        let prediction = model.predict(left, right, prior.as_ref(), iters, true, None)?;
        if prediction.disparities.len() != iters {
            return Err(Error::Internal(format!(
                "{} disparity maps for {iters} iterations",
                prediction.disparities.len()
            )));
        }
        let mut max_abs_disparity = 0.0f32;
        for (k, disparity) in prediction.disparities.iter().enumerate() {
            if disparity.dims() != [1, 1, size[0], size[1]] {
                return Err(Error::Shape(format!(
                    "iteration {k}: disparity {:?} for a {size:?} input",
                    disparity.dims()
                )));
            }
            let values = to_vec(disparity.clone());
            if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
                return Err(Error::not_finite(format!("iteration {k}'s disparity ({bad})")));
            }
            max_abs_disparity = values.iter().fold(0.0, |m, v| m.max(v.abs()));
        }
        Ok(SmokeReport { parameters, iterations: iters, max_abs_disparity })
    };
    // A panic inside the network is a bug of a stage, but `check` should report it as this run's
    // failure and go on with the others.
    catch_unwind(AssertUnwindSafe(run)).unwrap_or_else(|panic| {
        Err(Error::Internal(format!("the forward pass panicked: {}", Error::panic_message(&*panic))))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_counts_are_grouped_by_thousands() {
        let report = |parameters| SmokeReport { parameters, iterations: 1, max_abs_disparity: 0.0 };
        assert_eq!(report(11_116_176).parameters_text(), "11,116,176 (11.12 M)");
        assert_eq!(report(999).parameters_text(), "999 (0.00 M)");
        assert_eq!(report(1_000).parameters_text(), "1,000 (0.00 M)");
    }
}
