//! `dgstereo ablate`: trains (or reuses) every run of the given experiment files, evaluates each
//! final model and writes the ablation table (Markdown, CSV, JSON) into `--out`.
//!
//! Each run trains into `--out/<run name>`. A run folder holding a finished run (`summary.json`
//! and `model.safetensors`) is reused as is; one holding checkpoints only is resumed. Every run is
//! scored on its held-out synthetic validation set (`[data.validation]`, column `synthetic`) and
//! on each of its `[[benchmarks]]` (a real data set under its protocol: EPE and the protocol's
//! headline rate); the table's columns are the union over the runs, NaN where a run lacks one.
//! Runs that differ only in `train.seed` form one row (mean ± std over the seeds,
//! [`dgstereo_train::ablation_table`]). Before any run trains, every run's data, initial weights
//! and benchmark folders are checked ([`dgstereo_train::preflight`]), so a wrong benchmark path
//! costs seconds, not a trained row. Where a row is one of the paper's, the rows' means also
//! fill the paper's four ablation tables (`paper-tables.md`, `paper-table{2,3,4,5}.csv`): rows are
//! matched by name and columns to benchmarks by name, and `--paper` sets the published figures
//! and our distance from them beside ours.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;
use dgstereo_core::DeviceChoice;
use dgstereo_train::ablation::{AblationTable, FinishedRun, TABLE_METRICS, evaluate_benchmark, evaluate_finished_run};
use dgstereo_train::ablation_plot::{RowCurves, validation_series, write_ablation_plot};
use dgstereo_train::ablation_table::mean_metrics;
use dgstereo_train::paper_report::{RunScores, compare_with_paper, write_paper_tables};
use dgstereo_train::preflight::preflight;
use dgstereo_train::run::{checkpoint_dir, is_finished};

use super::train::{folder_name, parts_of, train_one};

/// Options of `dgstereo ablate`.
#[derive(Args)]
pub struct AblateArgs {
    /// Experiment files; every run of each is a row, in order.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Output folder: one sub-folder per run, and the tables.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Train this many steps instead of each file's `train.steps`.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: Option<u64>,
    /// `cpu` or `gpu`.
    #[arg(long, default_value = "cpu")]
    pub device: DeviceChoice,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Show the paper's published figures beside ours in its tables: ours, the paper's, and ours
    /// minus the paper's.
    #[arg(long)]
    pub paper: bool,
    /// Train nothing: score the finished runs again (their scores are otherwise reused while
    /// neither the model nor the benchmarks changed); unfinished runs are left out.
    #[arg(long)]
    pub rescore: bool,
}

pub fn run(a: AblateArgs) -> anyhow::Result<ExitCode> {
    let stop = crate::stop_signals::StopSignals::install()?;
    let runs = dgstereo_experiment::load_all(&a.files)?;
    let device = a.device.device()?;
    // Everything every run reads, checked before the first one trains.
    let mut pairs: Vec<(String, usize)> =
        vec![("synthetic".into(), runs.first().map_or(0, |r| r.config.data.validation.count))];
    for run in &runs {
        let parts = parts_of(run.config.clone(), a.steps);
        let found = preflight(&parts, &run.config.benchmarks)
            .with_context(|| format!("{}: run '{}'", run.source.display(), run.name))?;
        for (b, n) in run.config.benchmarks.iter().zip(found.benchmark_pairs) {
            pairs.push((b.label().to_string(), n));
        }
    }
    std::fs::create_dir_all(&a.out).map_err(|e| dgstereo_core::Error::io(&a.out, e))?;
    let synthetic = "synthetic".to_string();
    let mut columns: Vec<(String, String)> = TABLE_METRICS.iter().map(|m| (synthetic.clone(), m.to_string())).collect();
    for b in runs.iter().flat_map(|r| &r.config.benchmarks) {
        for m in b.table_metrics() {
            let column = (b.label().to_string(), m.to_string());
            if !columns.contains(&column) {
                columns.push(column);
            }
        }
    }
    let mut table = AblationTable::new(columns);
    for (b, n) in &pairs {
        table.set_pairs(b, *n);
    }
    let losses: Vec<&str> = runs.iter().map(|r| r.config.loss.kind()).collect();
    if losses.iter().any(|k| *k != losses[0]) {
        let mut kinds = losses.clone();
        kinds.dedup();
        table.notes.push(format!(
            "The rows train with different losses ({}): their training losses are not comparable; the validation EPE in ablation.png is.",
            kinds.join(", ")
        ));
    }
    let mut scored: Vec<RunScores> = Vec::new();
    for run in runs {
        let name = run.name.clone();
        let out = a.out.join(folder_name(&name));
        let benchmarks = run.config.benchmarks.clone();
        let parts = parts_of(run.config, a.steps);
        if is_finished(&out) {
            let stored = std::fs::read_to_string(out.join("config.toml")).unwrap_or_default();
            let differences = dgstereo_train::run_identity::training_differences(&stored, &parts.resolved_toml)?;
            if !differences.is_empty() {
                return Err(dgstereo_train::run_identity::another_run(&out, &differences))
                    .with_context(|| format!("run '{name}'"));
            }
            println!("{name}: finished run found in {}, reusing it", out.display());
        } else if a.rescore {
            println!("{name}: not finished in {}, left out (--rescore trains nothing)", out.display());
            continue;
        } else {
            let resume = checkpoint_dir(&out).is_dir()
                && !dgstereo_train::checkpoint::list_checkpoints(&checkpoint_dir(&out))?.is_empty();
            if train_one(parts.clone(), &out, resume, !a.quiet, &device, &stop)?.stopped {
                return Ok(stop.exit_code());
            }
        }
        let scores = match cached_scores(&out, &parts, &benchmarks).filter(|_| !a.rescore) {
            Some(scores) => {
                println!("{name}: scores reused (model and benchmarks unchanged)");
                scores
            }
            None => {
                let scores = score(&name, &parts, &benchmarks, &out, &device)?;
                save_scores(&out, &parts, &benchmarks, &scores)?;
                scores
            }
        };
        table.push(&name, parts.train.seed, parts.train.steps, &scores);
        table.write(&a.out)?;
        write_ablation_plot(&row_curves(&table, &a.out), &a.out.join("ablation.png"))?;
        scored.push(RunScores { run: name, scores });
    }
    println!("\n{}", table.to_markdown());
    println!("tables written to {}/ablation.{{md,csv,json}}, curves to ablation.png", a.out.display());
    // The paper's tables, by row (the mean over a row's seeds), where a row is one of the paper's.
    let rows = rows_of(&table, &scored);
    let comparisons = compare_with_paper(&rows);
    if comparisons.iter().any(|t| t.has_runs()) {
        write_paper_tables(&comparisons, &a.out, a.paper)?;
        for paper_table in comparisons.iter().filter(|t| t.has_runs()) {
            println!("{}", paper_table.to_markdown(a.paper));
        }
        println!("the paper's tables written to {}/paper-tables.md and paper-table{{2,3,4,5}}.csv", a.out.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// Scores a finished run on its validation set (`synthetic`) and its benchmarks.
fn score(
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
fn cached_scores(
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
fn save_scores(
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

/// Each row's validation curves, one per seed, from its runs' logs.
fn row_curves(table: &AblationTable, out: &std::path::Path) -> Vec<RowCurves> {
    table
        .rows
        .iter()
        .map(|row| RowCurves {
            name: row.name.clone(),
            seeds: row
                .seeds
                .iter()
                .map(|s| validation_series(&out.join(folder_name(&s.run)).join("log.jsonl")))
                .collect(),
        })
        .collect()
}

/// Each row's scores: per benchmark, the mean of its seeds' metrics.
fn rows_of(table: &AblationTable, runs: &[RunScores]) -> Vec<RunScores> {
    table
        .rows
        .iter()
        .map(|row| {
            let seeds: Vec<&RunScores> = runs.iter().filter(|r| row.seeds.iter().any(|s| s.run == r.run)).collect();
            let mut benchmarks: Vec<String> = Vec::new();
            for (b, _) in seeds.iter().flat_map(|r| &r.scores) {
                if !benchmarks.contains(b) {
                    benchmarks.push(b.clone());
                }
            }
            let scores = benchmarks
                .into_iter()
                .map(|b| {
                    let all: Vec<_> =
                        seeds.iter().filter_map(|r| r.scores.iter().find(|(n, _)| *n == b).map(|(_, m)| *m)).collect();
                    let mean = mean_metrics(&all);
                    (b, mean)
                })
                .collect();
            RunScores { run: row.name.clone(), scores }
        })
        .collect()
}
