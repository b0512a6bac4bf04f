//! The ablation table: rows = configurations, columns = benchmark × metric, in the paper's
//! layout, with seeds as an axis of their own.
//!
//! Design decision: a claim that one row beats another must survive the spread between seeds.
//! Runs that differ only in `train.seed` (a `[sweep]` over it names them `.../train.seed=N`) are
//! one row ([`row_name`]): each value is the mean over the row's seeds, shown `mean ± std` (the
//! sample standard deviation) with the row's seed count `n`. A row is **bold** only where its mean
//! beats the next row's by more than the larger of the two standard deviations, and the second
//! best is <u>underlined</u> by the same rule against the third. Every metric here is an error
//! (EPE in px, bad-T and D1 in % of the valid pixels), so lower is better; the Markdown ends with
//! a legend saying so, with the pairs behind each benchmark, then each row's description and
//! seeds and each benchmark's settings (its folder, iterations, size limit), so the table says
//! what was measured and how. CSV (`<metric> std` beside each metric, `n`, `steps`) and JSON (the
//! per-seed values, descriptions and settings too) hold the same numbers unformatted.

use std::path::Path;

use dgstereo_core::Result;
use dgstereo_eval::Metrics;
use serde_json::json;

/// The metrics of the table (names of `dgstereo_eval::METRIC_NAMES`).
pub const TABLE_METRICS: [&str; 3] = ["epe", "bad-1", "bad-3"];

/// The row a run belongs to: its name without the `train.seed=...` part of a sweep's suffix
/// (`paper/+dgia/train.seed=2` and `paper/+dgia/loss.tau=0.8,train.seed=2` go to `paper/+dgia`
/// and `paper/+dgia/loss.tau=0.8`).
pub fn row_name(run: &str) -> String {
    let Some((head, tail)) = run.rsplit_once('/') else { return run.to_string() };
    if !tail.contains('=') {
        return run.to_string();
    }
    let kept: Vec<&str> = tail.split(',').filter(|part| !part.starts_with("train.seed=")).collect();
    if kept.is_empty() { head.to_string() } else { format!("{head}/{}", kept.join(",")) }
}

/// The unit of a metric of [`dgstereo_eval::METRIC_NAMES`].
pub fn unit(metric: &str) -> &'static str {
    if metric == "epe" { "px" } else { "%" }
}

/// One seed's run of a row and its values, aligned with [`AblationTable::columns`].
#[derive(Debug, Clone, PartialEq)]
pub struct SeedScores {
    /// The run's name.
    pub run: String,
    /// Its `train.seed`.
    pub seed: u64,
    /// One value per column (NaN when unknown).
    pub values: Vec<f64>,
}

/// One row: the runs of one configuration, one per seed.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationRow {
    /// The row's name ([`row_name`] of its runs).
    pub name: String,
    /// Training steps of its runs (the first run's, should they differ).
    pub steps: usize,
    /// Its runs, in the order they were added.
    pub seeds: Vec<SeedScores>,
}

impl AblationRow {
    /// The number of seeds.
    pub fn n(&self) -> usize {
        self.seeds.len()
    }

    fn finite(&self, column: usize) -> Vec<f64> {
        self.seeds.iter().map(|s| s.values[column]).filter(|v| v.is_finite()).collect()
    }

    /// The mean of column `column` over the seeds that have it (NaN when none has).
    pub fn mean(&self, column: usize) -> f64 {
        let v = self.finite(column);
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    }

    /// The sample standard deviation (`n - 1`) of column `column`; 0 for a single seed.
    pub fn std(&self, column: usize) -> f64 {
        let v = self.finite(column);
        if v.len() < 2 {
            return if v.is_empty() { f64::NAN } else { 0.0 };
        }
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
    }
}

/// A table of configurations against benchmark × metric columns.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AblationTable {
    /// `(benchmark, metric)` per column.
    pub columns: Vec<(String, String)>,
    /// The rows, in the order their first run was added.
    pub rows: Vec<AblationRow>,
    /// The number of pairs each benchmark scores, by benchmark name.
    pub pairs: Vec<(String, usize)>,
    /// Remarks printed under the legend (rows trained with different losses).
    pub notes: Vec<String>,
    /// Runs without current scores (failed, not finished, or stale), each with what is known
    /// of it.
    pub missing: Vec<(String, String)>,
    /// Each row's description, by row name.
    pub descriptions: Vec<(String, String)>,
    /// How each benchmark is scored, by benchmark name
    /// ([`BenchmarkConfig::settings`](dgstereo_eval::BenchmarkConfig::settings)).
    pub settings: Vec<(String, String)>,
}

impl AblationTable {
    /// A table with the given columns and no rows.
    pub fn new(columns: Vec<(String, String)>) -> Self {
        Self {
            columns,
            rows: Vec::new(),
            pairs: Vec::new(),
            notes: Vec::new(),
            missing: Vec::new(),
            descriptions: Vec::new(),
            settings: Vec::new(),
        }
    }

    /// Records the description of the row of run `run` (the first given for a row stands).
    pub fn describe_row(&mut self, run: &str, description: &str) {
        let row = row_name(run);
        if !self.descriptions.iter().any(|(r, _)| *r == row) {
            self.descriptions.push((row, description.to_string()));
        }
    }

    /// Records how `benchmark` is scored (shown under the legend).
    pub fn set_settings(&mut self, benchmark: &str, settings: &str) {
        match self.settings.iter_mut().find(|(b, _)| b == benchmark) {
            Some(entry) => entry.1 = settings.to_string(),
            None => self.settings.push((benchmark.to_string(), settings.to_string())),
        }
    }

    /// The lines under the legend: each row's seeds and description, each benchmark's settings.
    pub fn details(&self) -> String {
        let mut s = String::new();
        if !self.rows.is_empty() {
            s += "\nRows:\n\n";
            for row in &self.rows {
                let seeds: Vec<String> = row.seeds.iter().map(|x| x.seed.to_string()).collect();
                let plural = if seeds.len() == 1 { "" } else { "s" };
                s += &format!("- `{}` (seed{plural} {}, {} steps)", row.name, seeds.join(", "), row.steps);
                if let Some((_, d)) = self.descriptions.iter().find(|(r, _)| *r == row.name) {
                    s += &format!(": {d}");
                }
                s.push('\n');
            }
        }
        if !self.settings.is_empty() {
            s += "\nBenchmarks:\n\n";
            for (b, text) in &self.settings {
                s += &format!("- {b}: {text}\n");
            }
        }
        s
    }

    /// Records that `benchmark` scores `pairs` pairs (shown in the legend).
    pub fn set_pairs(&mut self, benchmark: &str, pairs: usize) {
        match self.pairs.iter_mut().find(|(b, _)| b == benchmark) {
            Some(entry) => entry.1 = pairs,
            None => self.pairs.push((benchmark.to_string(), pairs)),
        }
    }

    /// Adds run `run` (seed `seed`, `steps` steps) with per-benchmark metrics (missing
    /// benchmarks give NaN) to the row of its [`row_name`].
    pub fn push(&mut self, run: &str, seed: u64, steps: usize, metrics: &[(String, Metrics)]) {
        let values = self
            .columns
            .iter()
            .map(|(bench, metric)| {
                metrics.iter().find(|(b, _)| b == bench).and_then(|(_, m)| m.get(metric)).unwrap_or(f64::NAN)
            })
            .collect();
        let scores = SeedScores { run: run.to_string(), seed, values };
        let name = row_name(run);
        match self.rows.iter_mut().find(|r| r.name == name) {
            Some(row) => row.seeds.push(scores),
            None => self.rows.push(AblationRow { name, steps, seeds: vec![scores] }),
        }
    }

    /// Records run `run`, which has no scores, and why (`not finished (log: ...)`); it is a row of
    /// its own in every format, never a silent gap.
    pub fn push_missing(&mut self, run: &str, reason: &str) {
        self.missing.push((run.to_string(), reason.to_string()));
    }

    /// Per column, the best and second-best rows by mean, each only where it beats the next row
    /// by more than the larger of their standard deviations (lower is better).
    pub fn ranks(&self) -> Vec<(Option<usize>, Option<usize>)> {
        (0..self.columns.len())
            .map(|c| {
                let mut order: Vec<usize> =
                    (0..self.rows.len()).filter(|&r| self.rows[r].mean(c).is_finite()).collect();
                order.sort_by(|&a, &b| self.rows[a].mean(c).total_cmp(&self.rows[b].mean(c)));
                let beats = |k: usize| match (order.get(k), order.get(k + 1)) {
                    (Some(&a), Some(&b)) => {
                        let margin = self.rows[b].mean(c) - self.rows[a].mean(c);
                        let spread = self.rows[a].std(c).max(self.rows[b].std(c));
                        (margin > spread).then_some(a)
                    }
                    _ => None,
                };
                (beats(0), beats(1))
            })
            .collect()
    }

    /// What the table's marks, values and units mean, and the pairs behind each benchmark.
    pub fn legend(&self) -> String {
        let pairs: Vec<String> = self.pairs.iter().map(|(b, n)| format!("{b} {n}")).collect();
        let mut s = String::from(
            "Lower is better in every column: EPE in px, bad-T in % of the valid pixels whose error exceeds T px. \
             A value is the mean over the row's seeds (`n`), `± std` their sample standard deviation. \
             **Bold**: the best mean, ahead of the next row's by more than the larger of the two standard deviations; \
             <u>underlined</u>: the second best, ahead of the third by the same rule.",
        );
        if !pairs.is_empty() {
            s += &format!(" Pairs scored: {}.", pairs.join(", "));
        }
        for note in &self.notes {
            s += &format!(" {note}");
        }
        s
    }

    /// The table as Markdown, followed by its [`legend`](Self::legend).
    pub fn to_markdown(&self) -> String {
        let ranks = self.ranks();
        let mut s = String::from("| run | n | steps |");
        for (b, m) in &self.columns {
            s += &format!(" {b} {m} ({}) |", unit(m));
        }
        s += "\n|---|---:|---:|";
        s += &"---:|".repeat(self.columns.len());
        s.push('\n');
        for (r, row) in self.rows.iter().enumerate() {
            s += &format!("| {} | {} | {} |", row.name, row.n(), row.steps);
            for (c, rank) in ranks.iter().enumerate() {
                let (mean, std) = (row.mean(c), row.std(c));
                let text = match (mean.is_finite(), row.n() > 1 && std.is_finite()) {
                    (false, _) => "–".to_string(),
                    (true, true) => format!("{mean:.3} ± {std:.3}"),
                    (true, false) => format!("{mean:.3}"),
                };
                let text = match *rank {
                    (Some(best), _) if best == r => format!("**{text}**"),
                    (_, Some(second)) if second == r => format!("<u>{text}</u>"),
                    _ => text,
                };
                s += &format!(" {text} |");
            }
            s.push('\n');
        }
        for (run, reason) in &self.missing {
            s += &format!("| {run} | 0 | – | {reason} |{}\n", " – |".repeat(self.columns.len().saturating_sub(1)));
        }
        s.push('\n');
        s += &self.legend();
        s.push('\n');
        s += &self.details();
        s
    }

    /// The table as CSV: `run,n,steps`, then per column its mean and `<column> std`.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("run,n,steps");
        for (b, m) in &self.columns {
            s += &format!(",{b} {m},{b} {m} std");
        }
        s.push('\n');
        let number = |v: f64| if v.is_finite() { format!(",{v}") } else { ",".into() };
        for row in &self.rows {
            s += &format!("{},{},{}", row.name.replace(',', ";"), row.n(), row.steps);
            for c in 0..self.columns.len() {
                s += &number(row.mean(c));
                s += &number(row.std(c));
            }
            s.push('\n');
        }
        for (run, _) in &self.missing {
            s += &format!("{},0,{}\n", run.replace(',', ";"), ",".repeat(2 * self.columns.len()));
        }
        s
    }

    /// The table as JSON: columns (with units and pairs), and per row `n`, `steps`, the means
    /// (`values`), the standard deviations (`std`) and every seed's run and values (`seeds`).
    pub fn to_json(&self) -> serde_json::Value {
        let number = |v: f64| serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, Into::into);
        let by_column = |f: &dyn Fn(usize) -> f64| {
            let mut map = serde_json::Map::new();
            for (c, (b, m)) in self.columns.iter().enumerate() {
                map.insert(format!("{b}/{m}"), number(f(c)));
            }
            serde_json::Value::Object(map)
        };
        let columns: Vec<_> = self
            .columns
            .iter()
            .map(|(b, m)| {
                let pairs = self.pairs.iter().find(|(name, _)| name == b).map(|(_, n)| *n);
                let settings = self.settings.iter().find(|(name, _)| name == b).map(|(_, s)| s);
                json!({"benchmark": b, "metric": m, "unit": unit(m), "pairs": pairs, "settings": settings})
            })
            .collect();
        let rows: Vec<_> = self
            .rows
            .iter()
            .map(|r| {
                let seeds: Vec<_> = r
                    .seeds
                    .iter()
                    .map(|s| json!({"run": s.run, "seed": s.seed, "values": by_column(&|c| s.values[c])}))
                    .collect();
                let description = self.descriptions.iter().find(|(row, _)| *row == r.name).map(|(_, d)| d);
                json!({"run": r.name, "description": description, "n": r.n(), "steps": r.steps,
                       "values": by_column(&|c| r.mean(c)), "std": by_column(&|c| r.std(c)), "seeds": seeds})
            })
            .collect();
        let missing: Vec<_> = self.missing.iter().map(|(run, reason)| json!({"run": run, "reason": reason})).collect();
        json!({"columns": columns, "rows": rows, "missing": missing, "lower_is_better": true})
    }

    /// Writes `ablation.md`, `ablation.csv` and `ablation.json` into `dir` (atomically).
    pub fn write(&self, dir: &Path) -> Result<()> {
        use dgstereo_train::checkpoint::write_atomic;
        write_atomic(&dir.join("ablation.md"), self.to_markdown().as_bytes())?;
        write_atomic(&dir.join("ablation.csv"), self.to_csv().as_bytes())?;
        write_atomic(&dir.join("ablation.json"), format!("{:#}\n", self.to_json()).as_bytes())
    }
}

/// The field-wise mean of `metrics` (a row's seeds, for the paper's tables); `valid_pixels` is
/// the total.
pub fn mean_metrics(metrics: &[Metrics]) -> Metrics {
    let n = metrics.len().max(1) as f64;
    let mean = std::array::from_fn(|i| metrics.iter().map(|m| m.values()[i]).sum::<f64>() / n);
    Metrics::from_values(mean, metrics.iter().map(|m| m.valid_pixels).sum())
}

/// The field-wise sample standard deviation of `metrics` (`n - 1`; a row's seeds).
pub fn std_metrics(metrics: &[Metrics]) -> Metrics {
    let mean = mean_metrics(metrics);
    let centre = mean.values();
    let n = metrics.len().saturating_sub(1).max(1) as f64;
    let squares = |i: usize| metrics.iter().map(|m| (m.values()[i] - centre[i]).powi(2)).sum::<f64>();
    Metrics::from_values(std::array::from_fn(|i| (squares(i) / n).sqrt()), mean.valid_pixels)
}
