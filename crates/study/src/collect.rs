//! The tables of a study from its run folders: what a study writes after its runs, and what
//! collecting a study (a Slurm study's last job) writes from whatever has finished.
//!
//! Design decision: the tables are built from the scores each run stored in its own folder
//! ([`crate::scores`]), never from the process that trained, so a study run locally and one run
//! as a Slurm array give the same bytes. A row's steps are those its runs' own records say they
//! trained ([`crate::record::recorded_steps`]), never what the command line asks. A run without
//! stored scores is a row saying why (failed, with the log's error; not finished), with its log's
//! path; so is a run whose folder holds a training other than its file now configures (stale,
//! with the keys that differ), whose scores would stand for another configuration.

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_eval::BenchmarkConfig;
use dgstereo_eval::published::Table1Row;
use dgstereo_experiment::ResolvedRun;
use dgstereo_train::run_identity::folder_differences;

use crate::ablation_plot::{RowCurves, validation_series, write_ablation_plot};
use crate::ablation_table::{AblationTable, TABLE_METRICS, mean_metrics, std_metrics};
use crate::paper_match::{BenchmarkMatch, match_benchmarks};
use crate::paper_report::{PaperComparison, RunScores, compare_with_paper, write_paper_tables};
use crate::paper_table1::{table1_comparison, table1_model};
use crate::record::{Study, recorded_steps, why_missing};
use crate::runs::{parts_of, run_folder};
use crate::scores::{SYNTHETIC, cached_scores};

/// What collecting a study wrote, for the caller to show.
pub struct Collected {
    /// The ablation table (also in `ablation.{md,csv,json}`).
    pub table: AblationTable,
    /// The paper's tables, each filled where the study has its rows.
    pub comparisons: Vec<PaperComparison>,
    /// Which benchmark of the study fills each of the paper's data sets.
    pub matches: Vec<BenchmarkMatch>,
    /// The number of runs collected.
    pub runs: usize,
}

impl Collected {
    /// Whether a row of the study is one of the paper's (and its tables were written).
    pub fn fills_paper_tables(&self) -> bool {
        self.comparisons.iter().any(PaperComparison::has_runs)
    }

    /// Whether every run has current scores.
    pub fn complete(&self) -> bool {
        self.table.missing.is_empty()
    }
}

/// Every benchmark of the study, each name once (the first run's entry of that name).
fn study_benchmarks(runs: &[ResolvedRun]) -> Vec<BenchmarkConfig> {
    let mut benchmarks: Vec<BenchmarkConfig> = Vec::new();
    for b in runs.iter().flat_map(|r| &r.config.benchmarks) {
        if !benchmarks.iter().any(|k| k.label() == b.label()) {
            benchmarks.push(b.clone());
        }
    }
    benchmarks
}

/// The table's columns, pairs, notes, descriptions and settings, without rows.
fn empty_table(runs: &[ResolvedRun], benchmarks: &[BenchmarkConfig]) -> AblationTable {
    let synthetic = SYNTHETIC.to_string();
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
/// `ablation.png` and, where a row is one of the paper's, its tables (`paper-tables.md`,
/// `paper-table{N}.csv`, with the published figures where `study.paper`): Tables 2 to 5 by run
/// name and, with `study.paper`, Table 1 where a run's network is one of its models
/// ([`table1_model`]).
///
/// # Errors
/// A run folder's configuration cannot be read, or a table cannot be written.
pub fn collect(runs: &[ResolvedRun], study: &Study, out: &Path) -> Result<Collected> {
    let benchmarks = study_benchmarks(runs);
    let mut table = empty_table(runs, &benchmarks);
    let mut scored: Vec<RunScores> = Vec::new();
    for run in runs {
        let folder = run_folder(out, &run.name);
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
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    table.write(out)?;
    write_ablation_plot(&row_curves(&table, out), &out.join("ablation.png"))?;
    let matches = match_benchmarks(&benchmarks);
    let rows = rows_of(&table, &scored);
    // Table 1 compares models with the published ones: only where the study asks for the
    // paper's figures (`--paper`), since any RAFT-Stereo run is one of its models.
    let table1 = if study.paper { table1_comparison(&table1_models(&table, runs), &rows, &matches) } else { None };
    let mut comparisons: Vec<PaperComparison> = table1.into_iter().collect();
    comparisons.extend(compare_with_paper(&rows, &matches));
    let collected = Collected { table, comparisons, matches, runs: runs.len() };
    if collected.fills_paper_tables() {
        write_paper_tables(&collected.comparisons, &collected.matches, out, study.paper)?;
    }
    Ok(collected)
}

/// The study recorded in `out/study.json`, collected ([`collect`]).
///
/// # Errors
/// There is no study record, its files do not load, or [`collect`] fails.
pub fn collect_study(out: &Path) -> Result<(Study, Collected)> {
    let study = Study::read(out)?;
    let runs = dgstereo_experiment::load_all(&study.files)?;
    let collected = collect(&runs, &study, out)?;
    Ok((study, collected))
}

/// Each row of `table` whose runs' network is a model of the paper's Table 1, with its row there
/// ([`table1_model`]).
fn table1_models(table: &AblationTable, runs: &[ResolvedRun]) -> Vec<(String, &'static Table1Row)> {
    table
        .rows
        .iter()
        .filter_map(|row| {
            let run = runs.iter().find(|r| row.seeds.iter().any(|s| s.run == r.name))?;
            Some((row.name.clone(), table1_model(&run.config)?))
        })
        .collect()
}

/// Each row's validation curves, one per seed, from its runs' logs.
fn row_curves(table: &AblationTable, out: &Path) -> Vec<RowCurves> {
    table
        .rows
        .iter()
        .map(|row| RowCurves {
            name: row.name.clone(),
            seeds: row.seeds.iter().map(|s| validation_series(&run_folder(out, &s.run).join("log.jsonl"))).collect(),
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
