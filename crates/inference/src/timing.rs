//! Whole inference timed as a user waits for it (`dgstereo bench`): a model's prediction of one
//! pair of random images of a given size, warm-up runs first, each run's wall and CPU seconds,
//! the depth prior's share, and the multiply-accumulates its operations counted.
//!
//! Design decision: a run goes through [`StereoModel::predict`], the call [`crate::Engine`]
//! makes (padding, network, cropping), and the freed buffers are released before it as before
//! each pair of `infer`, so the figure is what `infer` pays per pair; the inputs are random
//! because the cost does not depend on their values. The count is that of the network's own
//! operations ([`dgstereo_kernels::count_work`]), the prior's left out. The values of the
//! disparity that are not finite are counted outside the timed spans: a narrow precision that
//! overflowed times a meaningless map, which the caller refuses to report.

use std::time::Instant;

use burn::tensor::Tensor;
use dgstereo_core::random_values::RandomValues;
use dgstereo_core::timing::process_cpu_seconds;
use dgstereo_core::{DepthPrior, InputPadder, Result};
use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_kernels::{ProductPrecision, count_work, with_products};
use dgstereo_model::StereoModel;
use dgstereo_model::profile::{Profile, profile_forward};
use dgstereo_prior::{Prior, PriorInput, PriorProvider};

/// One pair of random images and what runs on it.
pub struct TimedInference<'a> {
    model: &'a StereoModel,
    size: [usize; 2],
    iters: usize,
    implementation: CorrelationImplementation,
    products: ProductPrecision,
    provider: Option<&'a Prior>,
    left: Tensor<4>,
    right: Tensor<4>,
    /// A model with a prior and no provider takes this random one, made outside the runs.
    given_prior: Option<DepthPrior>,
}

/// The seconds of one timed run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunSeconds {
    /// Wall-clock seconds of the whole prediction, prior included.
    pub wall: f64,
    /// CPU seconds of the process over the run (all threads); NaN where the system does not
    /// report them.
    pub cpu: f64,
    /// Seconds of the depth prior (both views), with a provider.
    pub prior: Option<f64>,
}

/// The timed runs and the network's work per run.
#[derive(Clone, Debug, PartialEq)]
pub struct InferenceTiming {
    /// One entry per timed run (the warm-up's left out).
    pub runs: Vec<RunSeconds>,
    /// Multiply-accumulates of the network's operations in one run (direct convolutions).
    pub macs: u64,
    /// Values of the last run's disparity that are not finite.
    pub non_finite: usize,
}

impl<'a> TimedInference<'a> {
    /// Random images of `size` (`[height, width]`) on the model's device for `model`, run
    /// `iters` iterations with `implementation` and `products`; `provider` computes the prior in
    /// each run, else a model with a prior takes a random one.
    pub fn new(
        model: &'a StereoModel,
        size: [usize; 2],
        iters: usize,
        implementation: CorrelationImplementation,
        products: ProductPrecision,
        provider: Option<&'a Prior>,
    ) -> Self {
        let ([h, w], device) = (size, &model.device);
        // From a generator of their own: the backend's is process-wide, and a draw from it
        // while another thread initialises a seeded run would change that run's weights.
        let mut random = RandomValues::new(0);
        let (left, right) =
            (random.uniform([1, 3, h, w], [0.0, 255.0], device), random.uniform([1, 3, h, w], [0.0, 255.0], device));
        let given_prior = model.config.needs_prior().then(|| DepthPrior {
            left: random.uniform([1, 1, h, w], [0.1, 1.0], device),
            right: random.uniform([1, 1, h, w], [0.1, 1.0], device),
        });
        Self { model, size, iters, implementation, products, provider, left, right, given_prior }
    }

    /// The padded size the network sees, `[height, width]`.
    pub fn padded(&self) -> [usize; 2] {
        let [h, w] = self.size;
        InputPadder::new(h, w, self.model.config.pad_divisor()).padded()
    }

    /// Runs `warmup` untimed predictions, then times `runs`.
    ///
    /// # Errors
    /// The prior's or the model's error.
    pub fn time(&self, warmup: usize, runs: usize) -> Result<InferenceTiming> {
        for _ in 0..warmup {
            self.run_once()?;
        }
        let mut timing = InferenceTiming { runs: Vec::with_capacity(runs), macs: 0, non_finite: 0 };
        for _ in 0..runs {
            let (seconds, macs, non_finite) = self.run_once()?;
            timing.runs.push(seconds);
            (timing.macs, timing.non_finite) = (macs, non_finite);
        }
        Ok(timing)
    }

    /// One prediction: its seconds, its network's multiply-accumulates and the values of its
    /// disparity that are not finite.
    fn run_once(&self) -> Result<(RunSeconds, u64, usize)> {
        let cpu = process_cpu_seconds();
        // As the engine does before each pair (outside the timed span): every run has one size,
        // so the passes reuse each other's freed buffers.
        dgstereo_kernels::allocator::release_before_pass(self.size);
        let start = Instant::now();
        let (computed, prior_seconds) = match self.provider {
            Some(p) => {
                let input = PriorInput {
                    left: self.left.clone(),
                    right: self.right.clone(),
                    gt_disparity: None,
                    names: vec!["bench".into()],
                };
                (p.provide(&input)?, Some(start.elapsed().as_secs_f64()))
            }
            None => (None, None),
        };
        let prior = computed.as_ref().or(self.given_prior.as_ref());
        let (left, right) = (self.left.clone(), self.right.clone());
        let (out, work) = with_products(self.products, || {
            count_work(|| self.model.predict(left, right, prior, self.iters, false, Some(self.implementation)))
        });
        let data = out?.last().into_data(); // waits for asynchronous backends
        let wall = start.elapsed().as_secs_f64();
        let cpu = process_cpu_seconds().zip(cpu).map_or(f64::NAN, |(b, a)| b - a);
        // Outside both timed spans: a narrow precision that overflowed times a meaningless map.
        let non_finite = data.convert::<f32>().iter::<f32>().filter(|v| !v.is_finite()).count();
        Ok((RunSeconds { wall, cpu, prior: prior_seconds }, work.macs, non_finite))
    }

    /// Each stage of one forward pass timed apart ([`profile_forward`]), on the padded pair
    /// with the random prior.
    ///
    /// # Errors
    /// The model's error.
    pub fn stages(&self) -> Result<Profile> {
        let [h, w] = self.size;
        let padder = InputPadder::new(h, w, self.model.config.pad_divisor());
        let (left, right) = (padder.pad(self.left.clone()), padder.pad(self.right.clone()));
        let prior = self
            .given_prior
            .as_ref()
            .map(|p| DepthPrior { left: padder.pad(p.left.clone()), right: padder.pad(p.right.clone()) });
        let mut config = self.model.config.clone();
        config.correlation.implementation = self.implementation;
        let mut network = self.model.network.clone();
        network.correlation.implementation = self.implementation;
        with_products(self.products, || profile_forward(&network, &config, left, right, prior.as_ref(), self.iters))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_are_timed_after_the_warm_up_and_the_work_counted() {
        let device = dgstereo_core::default_device();
        let config = dgstereo_model::ModelConfig::default();
        let model = StereoModel::new(config.init(&device).unwrap(), config, device);
        let timed =
            TimedInference::new(&model, [32, 48], 1, CorrelationImplementation::Reg, ProductPrecision::F32, None);
        assert_eq!(timed.padded(), [32, 64]);
        let timing = timed.time(1, 2).unwrap();
        assert_eq!(timing.runs.len(), 2);
        assert!(timing.runs.iter().all(|r| r.wall > 0.0 && r.prior.is_none()), "{timing:?}");
        assert!(timing.macs > 0 && timing.non_finite == 0);
    }
}
