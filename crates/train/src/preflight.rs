//! What a run reads from disk, checked before anything trains.
//!
//! Design decision: an ablation is hours to days of training per row, and a benchmark is only
//! read after its row has trained. A benchmark folder that does not exist, or holds no pair with
//! ground truth, must stop the study before its first step, not after its first row: `ablate`
//! and `experiment check` run [`preflight`] on every run first. It lists the training sources
//! (as the trainer does), checks the initial weights, opens every benchmark and reads the header
//! of every file of every sample it will score (both views of one size, the ground truth complete
//! and of the left view's size: `dgstereo_data::headers`); each error names the key and the
//! absolute path it looked at.

use dgstereo_core::{Error, Result};
use dgstereo_eval::BenchmarkConfig;

use crate::batch::TrainingData;
use crate::trainer::TrainParts;

/// What [`preflight`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Preflight {
    /// The number of pairs each benchmark scores (its limit applied), in order.
    pub benchmark_pairs: Vec<usize>,
}

/// `path` made absolute against the working directory, for messages.
fn absolute(path: &std::path::Path) -> std::path::PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// Checks that every file and folder a run of `parts` scored on `benchmarks` reads is there:
/// the training sources (listed, with ground truth), `train.init`, `train.monocular_init` and
/// `train.feature_init`, and each benchmark (its
/// folder holds pairs with ground truth, and every sample it scores passes
/// [`SampleFiles::check_headers`](dgstereo_data::SampleFiles::check_headers)).
///
/// # Errors
/// [`Error::Config`] naming the key (`data.sources[0].root`, `train.init`,
/// `benchmarks[1].root`) and the absolute path; for a sample's file, the file's error (naming
/// it, and the left view where sizes differ) within the context of the benchmark's key.
pub fn preflight(parts: &TrainParts, benchmarks: &[BenchmarkConfig]) -> Result<Preflight> {
    TrainingData::new(&parts.data, &parts.train)?;
    // Weights names were resolved by the front end (`TrainParts::with_named_weights`).
    parts.check_named_weights_resolved()?;
    let t = &parts.train;
    let weights =
        [("train.init", &t.init), ("train.monocular_init", &t.monocular_init), ("train.feature_init", &t.feature_init)];
    for (key, weights) in weights {
        if let Some(file) = weights
            && !file.is_file()
        {
            return Err(Error::config(key, format!("{}: no such file", absolute(file).display())));
        }
    }
    let mut benchmark_pairs = Vec::with_capacity(benchmarks.len());
    for (i, b) in benchmarks.iter().enumerate() {
        let key = format!("benchmarks[{i}]");
        let (dataset, indices) = b.dataset().map_err(|e| e.within(&key))?;
        for &index in &indices {
            let files = &dataset.files[index];
            files
                .check_headers()
                .map_err(|e| e.context(format!("{key} (benchmark '{}'), sample '{}'", b.label(), files.name)))?;
        }
        benchmark_pairs.push(indices.len());
    }
    Ok(Preflight { benchmark_pairs })
}
