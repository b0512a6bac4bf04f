//! A run's scores in its own folder (`scores.json`): computed once, reused while neither the
//! final model nor the scoring configuration changed.
//!
//! The values are stored as their bits: JSON's decimal text does not give every f64 back
//! exactly, and tables built from stored scores must equal tables built from fresh ones (a Slurm
//! study's collecting job reads what its tasks stored).

use std::path::Path;

use burn::tensor::Device;
use dgstereo_core::Result;
use dgstereo_eval::{BenchmarkConfig, Metrics};
use dgstereo_train::TrainParts;

use crate::scoring::{FinishedRun, evaluate_benchmark, evaluate_finished_run};

/// The column of the run's held-out synthetic validation set.
pub const SYNTHETIC: &str = "synthetic";

/// Scores the finished run in folder `out` on its validation set ([`SYNTHETIC`]) and its
/// benchmarks, in that order; `scored` sees each score as it is computed (a benchmark can take
/// minutes), the caller shows it.
///
/// # Errors
/// The final model does not load, or a set cannot be scored (the error names the run and the
/// benchmark).
pub fn score(
    parts: &TrainParts,
    benchmarks: &[BenchmarkConfig],
    out: &Path,
    device: &Device,
    mut scored: impl FnMut(&str, &Metrics),
) -> Result<Vec<(String, Metrics)>> {
    let finished = FinishedRun::load(parts, out, device)?;
    let metrics = evaluate_finished_run(parts, &finished, device)?;
    scored(SYNTHETIC, &metrics);
    let mut scores = vec![(SYNTHETIC.to_string(), metrics)];
    for b in benchmarks {
        let m = evaluate_benchmark(parts, &finished, b, device)
            .map_err(|e| e.context(format!("run '{}': benchmark '{}'", parts.name, b.label())))?;
        scored(b.label(), &m);
        scores.push((b.label().to_string(), m));
    }
    Ok(scores)
}

/// What a run's scores depend on besides its training: the final model file (size and time)
/// and the scoring configuration (validation set and benchmarks).
fn scoring_key(out: &Path, parts: &TrainParts, benchmarks: &[BenchmarkConfig]) -> Option<serde_json::Value> {
    let model = std::fs::metadata(out.join("model.safetensors")).ok()?;
    let modified = model.modified().ok()?.duration_since(std::time::UNIX_EPOCH).ok()?.as_nanos().to_string();
    Some(serde_json::json!({
        "model": {"bytes": model.len(), "modified_ns": modified},
        "validation": parts.data.validation, "benchmarks": benchmarks,
    }))
}

/// The scores saved in `out/scores.json`, when their key is this run's now.
pub fn cached_scores(out: &Path, parts: &TrainParts, benchmarks: &[BenchmarkConfig]) -> Option<Vec<(String, Metrics)>> {
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("scores.json")).ok()?).ok()?;
    if saved["key"] != scoring_key(out, parts, benchmarks)? {
        return None;
    }
    let saved: Vec<(String, [u64; 8])> = serde_json::from_value(saved["scores"].clone()).ok()?;
    Some(saved.into_iter().map(|(b, bits)| (b, metrics_from_bits(bits))).collect())
}

/// A metric's values as their bits (JSON's decimal text does not give every f64 back exactly,
/// and reused scores must equal the computed ones), `valid_pixels` last.
fn metrics_bits(m: &Metrics) -> [u64; 8] {
    let mut bits = [m.valid_pixels; 8];
    for (b, v) in bits.iter_mut().zip(m.values()) {
        *b = v.to_bits();
    }
    bits
}

fn metrics_from_bits(b: [u64; 8]) -> Metrics {
    let f = |i: usize| f64::from_bits(b[i]);
    Metrics {
        epe: f(0),
        bad_0_5: f(1),
        bad_1: f(2),
        bad_2: f(3),
        bad_3: f(4),
        bad_4: f(5),
        d1_all: f(6),
        valid_pixels: b[7],
    }
}

/// Saves `scores` with their key into `out/scores.json` (nothing where the folder holds no final
/// model to key them by).
///
/// # Errors
/// The file cannot be written.
pub fn save_scores(
    out: &Path,
    parts: &TrainParts,
    benchmarks: &[BenchmarkConfig],
    scores: &[(String, Metrics)],
) -> Result<()> {
    let Some(key) = scoring_key(out, parts, benchmarks) else { return Ok(()) };
    let bits: Vec<(&String, [u64; 8])> = scores.iter().map(|(b, m)| (b, metrics_bits(m))).collect();
    let text = serde_json::json!({"key": key, "scores": bits});
    dgstereo_train::checkpoint::write_atomic(&out.join("scores.json"), format!("{text:#}\n").as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_round_trip_their_bits() {
        let m = Metrics {
            epe: 0.1,
            bad_0_5: 1.0 / 3.0,
            bad_1: f64::NAN,
            bad_2: 2.5,
            bad_3: 1e-300,
            bad_4: 0.0,
            d1_all: 7.0,
            valid_pixels: 42,
        };
        let back = metrics_from_bits(metrics_bits(&m));
        assert_eq!(back.values().map(f64::to_bits), m.values().map(f64::to_bits));
        assert_eq!(back.valid_pixels, 42);
    }
}
