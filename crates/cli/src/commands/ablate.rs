//! `dgstereo ablate`: trains (or reuses) every run of the given experiment files, evaluates each
//! final model and writes the ablation table (Markdown, CSV, JSON) into `--out`.
//!
//! Each run trains into `--out/<run name>`. A run folder holding a finished run (`summary.json`
//! and `model.safetensors`) is reused as is; one holding checkpoints only is resumed. Every run is
//! scored on its held-out synthetic validation set (`[data.validation]`, column `synthetic`) and
//! on each of its `[[benchmarks]]` (a real data set under its protocol: EPE and the protocol's
//! headline rate); the table's columns are the union over the runs, NaN where a run lacks one.
//! The same scores fill the paper's four ablation tables (`paper-tables.md`,
//! `paper-table{2,3,4,5}.csv`): rows are matched to runs and columns to benchmarks by name, and
//! `--paper` sets the published figures and our distance from them beside ours.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;
use dgstereo_core::DeviceChoice;
use dgstereo_train::ablation::{AblationTable, FinishedRun, TABLE_METRICS, evaluate_benchmark, evaluate_finished_run};
use dgstereo_train::paper_report::{RunScores, compare_with_paper, write_paper_tables};
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
}

pub fn run(a: AblateArgs) -> anyhow::Result<ExitCode> {
    let runs = dgstereo_experiment::load_all(&a.files)?;
    let device = a.device.device()?;
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
    let mut scored: Vec<RunScores> = Vec::new();
    for run in runs {
        let name = run.name.clone();
        let out = a.out.join(folder_name(&name));
        let benchmarks = run.config.benchmarks.clone();
        let parts = parts_of(run.config, a.steps);
        if is_finished(&out) {
            let stored = std::fs::read_to_string(out.join("config.toml")).unwrap_or_default();
            if stored != parts.resolved_toml {
                anyhow::bail!(
                    "{}: holds a finished run of another configuration than '{name}' resolves to now; remove the folder or choose another --out",
                    out.display()
                );
            }
            println!("{name}: finished run found in {}, reusing it", out.display());
        } else {
            let resume = checkpoint_dir(&out).is_dir()
                && !dgstereo_train::checkpoint::list_checkpoints(&checkpoint_dir(&out))?.is_empty();
            train_one(parts.clone(), &out, resume, !a.quiet, &device)?;
        }
        let finished = FinishedRun::load(&parts, &out, &device)?;
        let metrics = evaluate_finished_run(&parts, &finished, &device)?;
        println!(
            "{name}: {synthetic} EPE {:.3} px, bad-1 {:.2} %, bad-3 {:.2} %",
            metrics.epe, metrics.bad_1, metrics.bad_3
        );
        let mut scores = vec![(synthetic.clone(), metrics)];
        for b in &benchmarks {
            let m = evaluate_benchmark(&parts, &finished, b, &device)
                .with_context(|| format!("run '{name}': benchmark '{}'", b.label()))?;
            let shown: Vec<String> =
                b.table_metrics().iter().map(|k| format!("{k} {:.3}", m.get(k).unwrap_or(f64::NAN))).collect();
            println!("{name}: {} ({} iterations) {}", b.label(), b.iters, shown.join(", "));
            scores.push((b.label().to_string(), m));
        }
        table.push(&name, &scores);
        table.write(&a.out)?;
        scored.push(RunScores { run: name, scores });
        write_paper_tables(&compare_with_paper(&scored), &a.out, a.paper)?;
    }
    println!("\n{}", table.to_markdown());
    for paper_table in compare_with_paper(&scored).iter().filter(|t| t.has_runs()) {
        println!("{}", paper_table.to_markdown(a.paper));
    }
    println!("tables written to {}/ablation.{{md,csv,json}}", a.out.display());
    println!("the paper's tables written to {}/paper-tables.md and paper-table{{2,3,4,5}}.csv", a.out.display());
    Ok(ExitCode::SUCCESS)
}
