//! The tables of a study from its run folders: what `ablate` writes after its runs, and what
//! `ablate --collect DIR` (a Slurm study's collecting job) writes from whatever has finished.
//!
//! Design decision: the tables are built from the scores each run stored in its own folder
//! ([`super::ablate_scores`]), never from the process that trained, so a study run locally and
//! one run as a Slurm array give the same bytes. `study.json` in the output folder records the
//! study (its experiment files, `--steps`, `--paper`) for `--collect`; a refused `ablate` never
//! writes it. A row's steps are those its runs' own records say they trained (`summary.json`,
//! else `config.toml`), never what the command line asks. A run without stored scores is a row
//! saying why (failed, with the log's error; not finished), with its log's path; so is a run
//! whose folder holds a training other than its file now configures (stale, with the keys that
//! differ), whose scores would stand for another configuration.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use dgstereo_experiment::ResolvedRun;
use dgstereo_train::ablation::{AblationTable, TABLE_METRICS};
use dgstereo_train::ablation_plot::{RowCurves, validation_series, write_ablation_plot};
use dgstereo_train::ablation_table::{mean_metrics, std_metrics};
use dgstereo_train::paper_match::match_benchmarks;
use dgstereo_train::paper_report::{RunScores, compare_with_paper, write_paper_tables};
use dgstereo_train::paper_tables::PAPER_TABLES;
use dgstereo_train::run::is_finished;
use dgstereo_train::run_identity::folder_differences;
use serde::{Deserialize, Serialize};

use super::ablate_scores::cached_scores;
use super::train::{folder_name, parts_of};

/// What `study.json` records of a study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Study {
    /// The experiment files (absolute), in order.
    pub files: Vec<PathBuf>,
    /// `--steps`, when given.
    pub steps: Option<u64>,
    /// `--paper`.
    pub paper: bool,
}

impl Study {
    /// Writes `out/study.json`.
    pub fn write(&self, out: &Path) -> anyhow::Result<()> {
        let text = serde_json::to_string_pretty(self)?;
        dgstereo_train::checkpoint::write_atomic(&out.join("study.json"), format!("{text}\n").as_bytes())?;
        Ok(())
    }

    /// Reads `out/study.json`.
    pub fn read(out: &Path) -> anyhow::Result<Self> {
        let path = out.join("study.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: no study here (ablate writes study.json into its --out)", path.display()))?;
        serde_json::from_str(&text).with_context(|| format!("{}: not a study record", path.display()))
    }
}

/// Why run folder `out` has no scores, with its log's path.
fn why_missing(out: &Path) -> String {
    let log = out.join("log.jsonl");
    let error = std::fs::read_to_string(&log).ok().and_then(|text| {
        text.lines()
            .rev()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .find(|v| v["kind"] == "error")
            .and_then(|v| v["message"].as_str().map(str::to_string))
    });
    match (is_finished(out), error) {
        (true, _) => format!("finished, not scored (log: {})", log.display()),
        (false, Some(message)) => format!("failed: {message} (log: {})", log.display()),
        (false, None) => format!("not finished (log: {})", log.display()),
    }
}

/// The steps the run in folder `out` trained, from its own record: `summary.json`'s `steps` for
/// a finished run, else its `config.toml`'s `train.steps`.
fn recorded_steps(out: &Path) -> Option<usize> {
    let summary = std::fs::read_to_string(out.join("summary.json")).ok();
    let finished =
        summary.and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok()).and_then(|v| v["steps"].as_u64());
    let configured = || {
        let text = std::fs::read_to_string(out.join("config.toml")).ok()?;
        text.parse::<toml::Table>().ok()?.get("train")?.get("steps")?.as_integer()
    };
    finished.or_else(|| configured().and_then(|s| u64::try_from(s).ok())).map(|s| s as usize)
}

/// Every benchmark of the study, each name once (the first run's entry of that name).
fn study_benchmarks(runs: &[ResolvedRun]) -> Vec<dgstereo_eval::BenchmarkConfig> {
    let mut benchmarks: Vec<dgstereo_eval::BenchmarkConfig> = Vec::new();
    for b in runs.iter().flat_map(|r| &r.config.benchmarks) {
        if !benchmarks.iter().any(|k| k.label() == b.label()) {
            benchmarks.push(b.clone());
        }
    }
    benchmarks
}

/// The table's columns, pairs, notes, descriptions and settings, without rows.
fn empty_table(runs: &[ResolvedRun], benchmarks: &[dgstereo_eval::BenchmarkConfig]) -> AblationTable {
    let synthetic = "synthetic".to_string();
    let mut columns: Vec<(String, String)> = TABLE_METRICS.iter().map(|m| (synthetic.clone(), m.to_string())).collect();
    for b in benchmarks {
        columns.extend(b.table_metrics().iter().map(|m| (b.label().to_string(), m.to_string())));
    }
    let mut table = AblationTable::new(columns);
    if let Some(first) = runs.first() {
        let v = &first.config.data.validation;
        table.set_pairs(&synthetic, v.count);
        let settings = format!(
            "held-out synthetic pairs of {}x{} (scene seeds from {}), {} iterations",
            v.scenes.width, v.scenes.height, v.seed, v.iters
        );
        table.set_settings(&synthetic, &settings);
    }
    for b in benchmarks {
        if let Ok((_, pairs)) = b.dataset() {
            table.set_pairs(b.label(), pairs.len());
        }
        table.set_settings(b.label(), &b.settings());
    }
    for run in runs {
        if let Some(d) = &run.config.description {
            table.describe_row(&run.name, d);
        }
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
    table
}

/// Builds and writes the tables of `runs` from their folders under `out`: `ablation.{md,csv,json}`,
/// `ablation.png` and, where a row is one of the paper's, its tables. Prints the table; the exit
/// status is a failure when a run has no current scores.
pub fn collect(runs: &[ResolvedRun], study: &Study, out: &Path) -> anyhow::Result<ExitCode> {
    let benchmarks = study_benchmarks(runs);
    let mut table = empty_table(runs, &benchmarks);
    let mut scored: Vec<RunScores> = Vec::new();
    for run in runs {
        let folder = out.join(folder_name(&run.name));
        let parts = parts_of(run.config.clone(), study.steps);
        let differences = folder_differences(&folder, &parts.resolved_toml)?;
        if !differences.is_empty() {
            let stale = format!(
                "stale: {} holds a run trained with another configuration than its file now gives ({})",
                folder.display(),
                differences.join("; ")
            );
            table.push_missing(&run.name, &stale);
            continue;
        }
        match cached_scores(&folder, &parts, &run.config.benchmarks) {
            Some(scores) => {
                let steps = recorded_steps(&folder).unwrap_or(parts.train.steps);
                table.push(&run.name, parts.train.seed, steps, &scores);
                scored.push(RunScores { run: run.name.clone(), scores, spread: Vec::new() });
            }
            None => table.push_missing(&run.name, &why_missing(&folder)),
        }
    }
    std::fs::create_dir_all(out).map_err(|e| dgstereo_core::Error::io(out, e))?;
    table.write(out)?;
    write_ablation_plot(&row_curves(&table, out), &out.join("ablation.png"))?;
    println!("\n{}", table.to_markdown());
    println!("tables written to {}/ablation.{{md,csv,json}}, curves to ablation.png", out.display());
    let matches = match_benchmarks(&benchmarks);
    let comparisons = compare_with_paper(&rows_of(&table, &scored), &matches);
    if comparisons.iter().any(|t| t.has_runs()) {
        write_paper_tables(&comparisons, &matches, out, study.paper)?;
        for paper_table in comparisons.iter().filter(|t| t.has_runs()) {
            println!("{}", paper_table.to_markdown(study.paper));
        }
        println!("the paper's columns, matched by data set:");
        for m in &matches {
            println!("  {}", m.describe());
        }
        println!("the paper's tables written to {}/paper-tables.md and paper-table{{2,3,4,5}}.csv", out.display());
    } else if study.paper {
        let mut names: Vec<&str> = Vec::new();
        for row in PAPER_TABLES.iter().flat_map(|t| t.rows) {
            if !names.contains(&row.run) {
                names.push(row.run);
            }
        }
        println!(
            "--paper: no row of this study is one of the paper's (its rows are the runs named {}), so there is \
             nothing to set beside the published figures",
            names.join(", ")
        );
    }
    if table.missing.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("{} of {} runs have no current scores (see the table)", table.missing.len(), runs.len());
        Ok(ExitCode::FAILURE)
    }
}

/// `dgstereo ablate --collect DIR`: the study recorded in `DIR/study.json`, collected.
pub fn collect_study(out: &Path) -> anyhow::Result<ExitCode> {
    let study = Study::read(out)?;
    let runs = dgstereo_experiment::load_all(&study.files)?;
    collect(&runs, &study, out)
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

/// Each row's scores: per benchmark, the mean of its seeds' metrics and, for several seeds,
/// their standard deviation.
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
            let mut scores = Vec::new();
            let mut spread = Vec::new();
            for b in benchmarks {
                let all: Vec<_> =
                    seeds.iter().filter_map(|r| r.scores.iter().find(|(n, _)| *n == b).map(|(_, m)| *m)).collect();
                scores.push((b.clone(), mean_metrics(&all)));
                if all.len() > 1 {
                    spread.push((b, std_metrics(&all)));
                }
            }
            RunScores { run: row.name.clone(), scores, spread }
        })
        .collect()
}
