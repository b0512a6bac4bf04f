//! Scoring a predictor over a whole data set into an [`EvalTable`].
//!
//! [`evaluate_dataset`] reads the samples ahead of the predictor on rayon's pool
//! ([`PrefetchLoader`]), calls the predictor on each, and scores the prediction on the sample's
//! valid ground truth (the data set's validity rule, plus the protocol's
//! [`ValidOptions`](crate::ValidOptions)) and, where the data set has an occlusion mask, on its
//! non-occluded part. Design decision: one bad sample (unreadable file, no ground truth, a
//! predictor error, a prediction of the wrong size) is recorded as a [`SampleFailure`] and the run
//! goes on, so a long evaluation is not lost to one file; the caller decides what a failure means
//! for its exit status.

use std::sync::Arc;

use dgstereo_core::{Error, Result};
use dgstereo_data::{Dataset, DisparityMap, PrefetchLoader, Sample};

use crate::metrics::accumulate;
use crate::protocol::Protocol;
use crate::table::{EvalRow, EvalTable};

/// A sample that could not be scored.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleFailure {
    /// The sample's name, or `#index` when it could not be read.
    pub name: String,
    /// What went wrong (names the file where a file is at fault).
    pub message: String,
}

/// The result of [`evaluate_dataset`].
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetEvaluation {
    /// One row per scored sample.
    pub table: EvalTable,
    /// The samples that could not be scored.
    pub failures: Vec<SampleFailure>,
}

/// Scores `predict` on the samples `indices` of `dataset` under `protocol` (see the module doc).
/// `on_sample` is called after each sample with its name and its row or failure.
pub fn evaluate_dataset<P, O>(
    dataset: Arc<dyn Dataset>,
    indices: Vec<usize>,
    protocol: Protocol,
    mut predict: P,
    mut on_sample: O,
) -> DatasetEvaluation
where
    P: FnMut(&Sample) -> Result<DisparityMap>,
    O: FnMut(std::result::Result<&EvalRow, &SampleFailure>),
{
    let mut table = EvalTable::new(protocol);
    let mut failures = Vec::new();
    let loader = PrefetchLoader::for_dataset(dataset, indices.clone(), 2);
    for (index, loaded) in indices.into_iter().zip(loader) {
        let outcome = loaded.map_err(|e| SampleFailure { name: format!("#{index}"), message: e.to_string() }).and_then(
            |sample| {
                score_sample(&sample, protocol, &mut predict)
                    .map_err(|e| SampleFailure { name: sample.name.clone(), message: e.to_string() })
            },
        );
        match outcome {
            Ok(row) => {
                on_sample(Ok(&row));
                table.push(row);
            }
            Err(f) => {
                on_sample(Err(&f));
                failures.push(f);
            }
        }
    }
    DatasetEvaluation { table, failures }
}

/// The row of one sample: the prediction scored on all valid pixels and on non-occluded ones.
pub fn score_sample<P>(sample: &Sample, protocol: Protocol, predict: &mut P) -> Result<EvalRow>
where
    P: FnMut(&Sample) -> Result<DisparityMap>,
{
    let (Some(gt), Some(valid)) = (&sample.disparity, &sample.valid) else {
        return Err(Error::sample(&sample.name, "no ground truth disparity to score against"));
    };
    let pred = predict(sample)?;
    let opts = protocol.valid_options();
    let all = accumulate(&pred, gt, Some(valid), opts)?;
    let noc = match &sample.nonoccluded {
        Some(m) => {
            let mask = valid.and(m).map_err(|e| e.context(format!("{}: occlusion mask", sample.name)))?;
            Some(accumulate(&pred, gt, Some(&mask), opts)?)
        }
        None => None,
    };
    Ok(EvalRow { name: sample.name.clone(), group: sample.group.clone(), all, noc })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dgstereo_data::{SyntheticConfig, SyntheticDataset};

    #[test]
    fn perfect_and_failing_predictors_are_scored_and_recorded() {
        let config = SyntheticConfig { width: 48, height: 32, ..SyntheticConfig::default() };
        let data = Arc::new(SyntheticDataset { config, seed: 7, len: 3 });
        let mut seen = 0;
        let result = evaluate_dataset(
            data,
            vec![0, 1, 2],
            Protocol::Generic,
            |s| {
                if s.name.ends_with("/8") {
                    return Err(Error::Internal("model failed".into()));
                }
                // Ground truth shifted by 0.75 px: EPE 0.75, bad-0.5 100 %, bad-1 0 %.
                let mut d = s.disparity.clone().unwrap();
                d.data.iter_mut().for_each(|v| *v += 0.75);
                Ok(d)
            },
            |_| seen += 1,
        );
        assert_eq!(seen, 3);
        assert_eq!(result.table.rows.len(), 2);
        assert_eq!(result.failures.len(), 1);
        assert_eq!(result.failures[0].name, "synthetic/8");
        let agg = &result.table.aggregates()[0];
        assert!((agg.all.epe - 0.75).abs() < 1e-4, "{}", agg.all.epe);
        assert_eq!(agg.all.bad_0_5, 100.0);
        assert_eq!(agg.all.bad_1, 0.0);
        let noc = agg.noc.expect("synthetic samples have occlusion masks");
        assert!(noc.valid_pixels > 0 && noc.valid_pixels <= agg.all.valid_pixels);
    }

    #[test]
    fn wrong_sized_prediction_is_a_failure() {
        let config = SyntheticConfig { width: 40, height: 24, ..SyntheticConfig::default() };
        let data = Arc::new(SyntheticDataset { config, seed: 1, len: 1 });
        let result =
            evaluate_dataset(data, vec![0], Protocol::Generic, |_| Ok(DisparityMap::filled(8, 8, 1.0)), |_| {});
        assert!(result.table.rows.is_empty());
        assert!(result.failures[0].message.contains("8x8"), "{}", result.failures[0].message);
    }
}
