//! The ablation table: rows = runs, columns = benchmark × metric, in the paper's layout.
//!
//! Every metric here is an error (EPE, bad-T), so lower is better: in the Markdown table the best
//! value of each column is **bold** and the second best <u>underlined</u>. CSV and JSON hold the
//! same numbers unformatted. [`evaluate_finished_run`] scores a finished run folder's final model
//! on the run's held-out synthetic validation set, [`evaluate_benchmark`] on a configured
//! benchmark through the eval crate's driver and the benchmark's protocol.

use std::path::Path;
use std::sync::Arc;

use burn::tensor::Device;
use dgstereo_core::{Error, Result};
use dgstereo_data::resize::{disparity_to_size, fit_scale, resize_disparity, resize_mask, resize_rgb};
use dgstereo_data::{Dataset, DisparityMap, Mask, Sample};
use dgstereo_eval::{BenchmarkConfig, Metrics, evaluate_dataset};
use dgstereo_model::RaftStereo;
use dgstereo_prior::Prior;
use serde_json::json;

use crate::batch::TrainingPair;
use crate::trainer::TrainParts;
use crate::validate::{ValidationSet, predict_pair};

/// The metrics of the table (names of `dgstereo_eval::METRIC_NAMES`).
pub const TABLE_METRICS: [&str; 3] = ["epe", "bad-1", "bad-3"];

/// One row: a run and its values, aligned with [`AblationTable::columns`].
#[derive(Debug, Clone, PartialEq)]
pub struct AblationRow {
    /// The run's name.
    pub name: String,
    /// One value per column (NaN when unknown).
    pub values: Vec<f64>,
}

/// A table of runs against benchmark × metric columns.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AblationTable {
    /// `(benchmark, metric)` per column.
    pub columns: Vec<(String, String)>,
    /// The runs, in the order given.
    pub rows: Vec<AblationRow>,
}

impl AblationTable {
    /// A table with the given columns and no rows.
    pub fn new(columns: Vec<(String, String)>) -> Self {
        Self { columns, rows: Vec::new() }
    }

    /// Adds the row of `name` from per-benchmark metrics (missing benchmarks give NaN).
    pub fn push(&mut self, name: &str, metrics: &[(String, Metrics)]) {
        let values = self
            .columns
            .iter()
            .map(|(bench, metric)| {
                metrics.iter().find(|(b, _)| b == bench).and_then(|(_, m)| m.get(metric)).unwrap_or(f64::NAN)
            })
            .collect();
        self.rows.push(AblationRow { name: name.to_string(), values });
    }

    /// Per column, the indices of the best and second-best rows (lowest values).
    pub fn ranks(&self) -> Vec<(Option<usize>, Option<usize>)> {
        (0..self.columns.len())
            .map(|c| {
                let mut order: Vec<usize> =
                    (0..self.rows.len()).filter(|&r| self.rows[r].values[c].is_finite()).collect();
                order.sort_by(|&a, &b| self.rows[a].values[c].total_cmp(&self.rows[b].values[c]));
                (order.first().copied(), order.get(1).copied())
            })
            .collect()
    }

    /// The table as Markdown: best bold, second underlined.
    pub fn to_markdown(&self) -> String {
        let ranks = self.ranks();
        let mut s = String::from("| run |");
        for (b, m) in &self.columns {
            s += &format!(" {b} {m} |");
        }
        s += "\n|---|";
        s += &"---:|".repeat(self.columns.len());
        s.push('\n');
        for (r, row) in self.rows.iter().enumerate() {
            s += &format!("| {} |", row.name);
            for (c, v) in row.values.iter().enumerate() {
                let text = if v.is_finite() { format!("{v:.3}") } else { "–".into() };
                let text = match ranks[c] {
                    (Some(best), _) if best == r => format!("**{text}**"),
                    (_, Some(second)) if second == r => format!("<u>{text}</u>"),
                    _ => text,
                };
                s += &format!(" {text} |");
            }
            s.push('\n');
        }
        s
    }

    /// The table as CSV (`run,benchmark metric,...`).
    pub fn to_csv(&self) -> String {
        let mut s = String::from("run");
        for (b, m) in &self.columns {
            s += &format!(",{b} {m}");
        }
        s.push('\n');
        for row in &self.rows {
            s += &row.name.replace(',', ";");
            for v in &row.values {
                s += &if v.is_finite() { format!(",{v}") } else { ",".into() };
            }
            s.push('\n');
        }
        s
    }

    /// The table as JSON: `{"columns": [{"benchmark", "metric"}], "rows": [{"run", "values": {..}}]}`.
    pub fn to_json(&self) -> serde_json::Value {
        let columns: Vec<_> = self.columns.iter().map(|(b, m)| json!({"benchmark": b, "metric": m})).collect();
        let rows: Vec<_> = self
            .rows
            .iter()
            .map(|r| {
                let mut values = serde_json::Map::new();
                for ((b, m), v) in self.columns.iter().zip(&r.values) {
                    values.insert(
                        format!("{b}/{m}"),
                        serde_json::Number::from_f64(*v).map_or(serde_json::Value::Null, Into::into),
                    );
                }
                json!({"run": r.name, "values": values})
            })
            .collect();
        json!({"columns": columns, "rows": rows})
    }

    /// Writes `ablation.md`, `ablation.csv` and `ablation.json` into `dir` (atomically).
    pub fn write(&self, dir: &Path) -> Result<()> {
        use crate::checkpoint::write_atomic;
        write_atomic(&dir.join("ablation.md"), self.to_markdown().as_bytes())?;
        write_atomic(&dir.join("ablation.csv"), self.to_csv().as_bytes())?;
        write_atomic(&dir.join("ablation.json"), format!("{:#}\n", self.to_json()).as_bytes())
    }
}

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
            crate::trainer::init_model(&parts.model, device, None)?,
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
        return Err(Error::Other(format!(
            "benchmark '{}': {} of {} sample(s) failed; first: {}: {}",
            benchmark.label(),
            result.failures.len(),
            result.failures.len() + result.table.rows.len(),
            f.name,
            f.message
        )));
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
