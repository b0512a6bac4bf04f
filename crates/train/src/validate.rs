//! Validation on held-out synthetic pairs with the eval crate's metrics.

use burn::tensor::Device;
use dgstereo_core::Result;
use dgstereo_data::DisparityMap;
use dgstereo_data::synthetic::generate;
use dgstereo_eval::{MetricSums, Metrics, ValidOptions, accumulate};
use dgstereo_experiment::ValidationConfig;
use dgstereo_model::{ModelConfig, RaftStereo};
use dgstereo_prior::Prior;

use crate::batch::{TrainingPair, to_tensors};
use crate::trainer::{batch_prior, forward_disparities};

/// The validation pairs, rendered once.
pub struct ValidationSet {
    pairs: Vec<TrainingPair>,
    iters: usize,
}

impl ValidationSet {
    /// Renders `config.count` synthetic pairs (scene seeds `seed .. seed + count`); fails when
    /// the photo folder the keys name does not load.
    pub fn new(config: &ValidationConfig) -> Result<Self> {
        config.scenes.check_files().map_err(|e| e.within("data.validation"))?;
        let synth = config.synthetic();
        let pairs = (0..config.count as u64)
            .map(|i| {
                let seed = config.seed.wrapping_add(i);
                let s = generate(&synth, seed);
                TrainingPair {
                    name: format!("validation/{seed}"),
                    left: s.left,
                    right: s.right,
                    disparity_nearest: s.disparity.clone(),
                    disparity: s.disparity,
                    valid: s.valid,
                }
            })
            .collect();
        Ok(Self { pairs, iters: config.iters.max(1) })
    }

    /// Whether there is nothing to validate on.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// Pooled metrics of `model` (plain device) over the set, one pair at a time.
    pub fn evaluate(
        &self,
        model: &RaftStereo,
        config: &ModelConfig,
        prior: &Prior,
        device: &Device,
    ) -> Result<Metrics> {
        let mut sums = MetricSums::default();
        for pair in &self.pairs {
            let pred = predict_pair(model, config, prior, pair, self.iters, device)?;
            sums.merge(&accumulate(&pred, &pair.disparity, Some(&pair.valid), ValidOptions::default())?);
        }
        Ok(sums.metrics())
    }
}

/// The disparity of one pair at its own size, the prior given the pair's ground truth (which
/// only a simulated prior reads).
pub fn predict_pair(
    model: &RaftStereo,
    config: &ModelConfig,
    prior: &Prior,
    pair: &TrainingPair,
    iters: usize,
    device: &Device,
) -> Result<DisparityMap> {
    let batch = to_tensors(std::slice::from_ref(pair), device)?;
    let p = batch_prior(prior, config.needs_prior(), &batch)?;
    let out = forward_disparities(model, config, batch.left, batch.right, p.as_ref(), iters, false)?;
    let pred = dgstereo_core::tensor::to_vec(out.last().expect("one iteration").clone());
    DisparityMap::from_vec(pair.left.width, pair.left.height, pred)
}
