//! Scoring the runs of an ablation: [`evaluate_finished_run`] scores a finished run folder's
//! final model on the run's held-out synthetic validation set, [`evaluate_benchmark`] on a
//! configured benchmark through the eval crate's driver and the benchmark's protocol. The table
//! they fill is [`crate::ablation_table`]; [`crate::scores`] stores them in the run's folder.

use std::path::Path;
use std::sync::Arc;

use burn::tensor::Device;
use dgstereo_core::{Error, Result};
use dgstereo_data::resize::{disparity_to_size, fit_scale, resize_disparity, resize_mask, resize_rgb};
use dgstereo_data::{Dataset, DisparityMap, Mask, Sample};
use dgstereo_eval::{BenchmarkConfig, Metrics, evaluate_dataset};
use dgstereo_model::RaftStereo;
use dgstereo_prior::Prior;

use dgstereo_train::batch::TrainingPair;
use dgstereo_train::trainer::TrainParts;
use dgstereo_train::validate::{ValidationSet, predict_pair};

/// The final model of a finished run and its prior provider, loaded once for all its scores
/// (a Depth Anything V2 provider alone is a ViT checkpoint to read).
pub struct FinishedRun {
    model: RaftStereo,
    prior: Prior,
}

impl FinishedRun {
    /// Loads `out/model.safetensors` into the run's model and builds the run's prior.
    pub fn load(parts: &TrainParts, out: &Path, device: &Device) -> Result<Self> {
        Self::with_weights(parts, &out.join("model.safetensors"), device)
    }

    /// Loads `weights` (a dgstereo `.safetensors` of the run's model) and builds the run's prior.
    pub fn with_weights(parts: &TrainParts, weights: &Path, device: &Device) -> Result<Self> {
        let model = dgstereo_model::checkpoint::load_safetensors(
            dgstereo_train::trainer::init_model(&parts.model, device, None)?,
            weights,
        )?;
        Ok(Self { model, prior: parts.prior.init(device)? })
    }
}

/// Scores the final model of a finished run on the run's held-out synthetic set.
pub fn evaluate_finished_run(parts: &TrainParts, run: &FinishedRun, device: &Device) -> Result<Metrics> {
    let set = ValidationSet::new(&parts.data.validation)?;
    if set.is_empty() {
        return Err(Error::config(
            "data.validation.count",
            format!("is 0: nothing to evaluate run '{}' on", parts.name),
        ));
    }
    set.evaluate(&run.model, &parts.model, &run.prior, device)
}

/// Scores the final model of a finished run on `benchmark` under its protocol.
///
/// The prior comes from the run's own provider; a simulated prior is simulated from the sample's
/// ground truth, as in training (an ablation device, not a deployable prior). Returns the
/// protocol's aggregate over all valid pixels; a sample that fails to load or run is an error
/// naming it (a table with silently missing samples would mislead).
pub fn evaluate_benchmark(
    parts: &TrainParts,
    run: &FinishedRun,
    benchmark: &BenchmarkConfig,
    device: &Device,
) -> Result<Metrics> {
    let (dataset, indices) = benchmark.dataset()?;
    let result = evaluate_dataset(
        Arc::new(dataset) as Arc<dyn Dataset>,
        indices,
        benchmark.dataset.protocol(),
        |sample| predict_sample(&run.model, parts, &run.prior, sample, benchmark, device),
        |_| {},
    );
    if let Some(f) = result.failures.first() {
        let what = format!(
            "benchmark '{}': {} of {} sample(s) failed; first",
            benchmark.label(),
            result.failures.len(),
            result.failures.len() + result.table.rows.len(),
        );
        return Err(Error::sample(&f.name, &f.message).context(what));
    }
    Ok(result.table.aggregates().remove(0).all)
}

/// The disparity of one benchmark sample at its own size (computed at `max_size` if smaller).
fn predict_sample(
    model: &RaftStereo,
    parts: &TrainParts,
    prior: &Prior,
    sample: &Sample,
    benchmark: &BenchmarkConfig,
    device: &Device,
) -> Result<DisparityMap> {
    let (w, h) = (sample.left.width, sample.left.height);
    let s = fit_scale(w, h, benchmark.max_size);
    // Without ground truth (only possible for a prior that does not need it) zeros stand in.
    let disparity = sample.disparity.clone().unwrap_or_else(|| DisparityMap::filled(w, h, 0.0));
    let valid = sample.valid.clone().unwrap_or_else(|| Mask::filled(w, h, false));
    let pair = if s < 1.0 {
        let (disparity, disparity_nearest) = resize_disparity(&disparity, s, s);
        TrainingPair {
            name: sample.name.clone(),
            left: resize_rgb(&sample.left, s, s),
            right: resize_rgb(&sample.right, s, s),
            disparity,
            disparity_nearest,
            valid: resize_mask(&valid, s, s),
        }
    } else {
        TrainingPair {
            name: sample.name.clone(),
            left: sample.left.clone(),
            right: sample.right.clone(),
            disparity_nearest: disparity.clone(),
            disparity,
            valid,
        }
    };
    let small = predict_pair(model, &parts.model, prior, &pair, benchmark.iters, device)?;
    disparity_to_size(&small, w, h)
}
