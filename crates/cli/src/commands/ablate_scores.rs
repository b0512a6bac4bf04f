//! A run's scores in its own folder (`scores.json`): computed once, reused while neither the
//! final model nor the scoring configuration changed.
//!
//! The values are stored as their bits: JSON's decimal text does not give every f64 back
//! exactly, and tables built from stored scores must equal tables built from fresh ones (a Slurm
//! study's collecting job reads what its tasks stored).

use anyhow::Context;
use dgstereo_train::ablation::{FinishedRun, evaluate_benchmark, evaluate_finished_run};

/// Scores a finished run on its validation set (`synthetic`) and its benchmarks.
pub fn score(
    name: &str,
    parts: &dgstereo_train::TrainParts,
    benchmarks: &[dgstereo_eval::BenchmarkConfig],
    out: &std::path::Path,
    device: &burn::tensor::Device,
) -> anyhow::Result<Vec<(String, dgstereo_eval::Metrics)>> {
    let finished = FinishedRun::load(parts, out, device)?;
    let metrics = evaluate_finished_run(parts, &finished, device)?;
    println!("{name}: synthetic EPE {:.3} px, bad-1 {:.2} %, bad-3 {:.2} %", metrics.epe, metrics.bad_1, metrics.bad_3);
    let mut scores = vec![("synthetic".to_string(), metrics)];
    for b in benchmarks {
        let m = evaluate_benchmark(parts, &finished, b, device)
            .with_context(|| format!("run '{name}': benchmark '{}'", b.label()))?;
        let shown: Vec<String> =
            b.table_metrics().iter().map(|k| format!("{k} {:.3}", m.get(k).unwrap_or(f64::NAN))).collect();
        println!("{name}: {} ({} iterations) {}", b.label(), b.iters, shown.join(", "));
        scores.push((b.label().to_string(), m));
    }
    Ok(scores)
}

/// What a run's scores depend on besides its training: the final model file (size and time)
/// and the scoring configuration (validation set and benchmarks).
fn scoring_key(
    out: &std::path::Path,
    parts: &dgstereo_train::TrainParts,
    benchmarks: &[dgstereo_eval::BenchmarkConfig],
) -> Option<serde_json::Value> {
    let model = std::fs::metadata(out.join("model.safetensors")).ok()?;
    let modified = model.modified().ok()?.duration_since(std::time::UNIX_EPOCH).ok()?.as_nanos().to_string();
    Some(serde_json::json!({
        "model": {"bytes": model.len(), "modified_ns": modified},
        "validation": parts.data.validation, "benchmarks": benchmarks,
    }))
}

/// The scores saved in `out/scores.json`, when their key is this run's now.
pub fn cached_scores(
    out: &std::path::Path,
    parts: &dgstereo_train::TrainParts,
    benchmarks: &[dgstereo_eval::BenchmarkConfig],
) -> Option<Vec<(String, dgstereo_eval::Metrics)>> {
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
fn metrics_bits(m: &dgstereo_eval::Metrics) -> [u64; 8] {
    let mut bits = [m.valid_pixels; 8];
    for (b, v) in bits.iter_mut().zip(m.values()) {
        *b = v.to_bits();
    }
    bits
}

fn metrics_from_bits(b: [u64; 8]) -> dgstereo_eval::Metrics {
    let f = |i: usize| f64::from_bits(b[i]);
    dgstereo_eval::Metrics {
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

/// Saves `scores` with their key into `out/scores.json`.
pub fn save_scores(
    out: &std::path::Path,
    parts: &dgstereo_train::TrainParts,
    benchmarks: &[dgstereo_eval::BenchmarkConfig],
    scores: &[(String, dgstereo_eval::Metrics)],
) -> anyhow::Result<()> {
    let Some(key) = scoring_key(out, parts, benchmarks) else { return Ok(()) };
    let bits: Vec<(&String, [u64; 8])> = scores.iter().map(|(b, m)| (b, metrics_bits(m))).collect();
    let text = serde_json::json!({"key": key, "scores": bits});
    dgstereo_train::checkpoint::write_atomic(&out.join("scores.json"), format!("{text:#}\n").as_bytes())?;
    Ok(())
}
