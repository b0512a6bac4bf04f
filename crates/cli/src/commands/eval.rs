//! `dgstereo eval`: runs a model over a data set and scores it under the benchmark's protocol.
//!
//! The data set's layout is read by the data crate, the model runs through the same [`dgstereo_inference::Engine`] as
//! `infer`, and the eval crate's driver scores each sample (all valid pixels, and non-occluded
//! ones where a mask exists) into a table printed as text and written as `eval.csv` and
//! `eval.json` in `--out`. The protocol follows the data set (KITTI: bad-3 pooled; Middlebury:
//! bad-2 per image; ETH3D: bad-1 per image; SceneFlow: FlyingThings3D finalpass TEST, bad-1
//! pooled; DrivingStereo: EPE and bad-3 per weather; folder: generic). `--split`, `--weather`
//! and `--subset` choose MiddEval3's resolution, one DrivingStereo weather and RAFT-Stereo's 400
//! FlyingThings3D pairs, as an experiment's `[[benchmarks]]` keys of the same names do. `--max-size` makes the
//! numbers differ from the benchmark's (it is for quick looks and tests) and is reported in the
//! output, as is the upscaling of small pairs that `--min-size` (default `auto`) applies to
//! 1/8-resolution models: the predictions are scored at the data set's size either way. For
//! a checkpoint that is a model of the paper's Table 1 (`raftstereo-sceneflow`,
//! `defomstereo-vits-sceneflow`, ...) on one of its data sets, the published figures are printed
//! beside ours ([`dgstereo_eval::published`]).

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::bail;
use clap::Args;
use dgstereo_data::Dataset;
use dgstereo_data::datasets::{DrivingStereoWeather, FlyingThingsTestSubset, MiddleburySplit, middeval3_splits_in};
use dgstereo_eval::{BenchmarkConfig, DatasetKind, evaluate_dataset, published};

use crate::engine::{ModelArgs, error_line, flag_names, load_engine};

/// Options of `dgstereo eval`.
#[derive(Args)]
pub struct EvalArgs {
    /// Data set layout: middlebury (the MiddEval3 folder with --split, or a folder of scene
    /// folders), eth3d (two-view training), kitti2012, kitti2015 (training folders), sceneflow
    /// (FlyingThings3D finalpass TEST), drivingstereo (weather subsets), folder (pairs with
    /// `*disp*` or disp0GT ground truth, e.g. assets/cones).
    #[arg(long, required_unless_present = "merge")]
    dataset: Option<DatasetKind>,
    /// Root folder of the data set.
    #[arg(long, required_unless_present = "merge")]
    root: Option<PathBuf>,
    /// Middlebury: the MiddEval3 split Q, H or F (--root is then the MiddEval3 folder).
    #[arg(long)]
    split: Option<MiddleburySplit>,
    /// DrivingStereo: score one weather (sunny, cloudy, foggy, rainy) instead of all present.
    #[arg(long)]
    weather: Option<DrivingStereoWeather>,
    /// SceneFlow: all TEST pairs, or raft-stereo-400 (RAFT-Stereo's validation subset).
    #[arg(long)]
    subset: Option<FlyingThingsTestSubset>,
    /// Output folder for eval.csv and eval.json.
    #[arg(short, long, default_value = "out/eval")]
    out: PathBuf,
    /// Evaluate only the first N samples.
    #[arg(long)]
    limit: Option<usize>,
    /// Score only shard I of N (`--shard 0/4`): every Nth sample from the Ith; `eval --merge`
    /// combines the shards' folders into the unsharded table.
    #[arg(long)]
    shard: Option<dgstereo_eval::shards::Shard>,
    /// Merge the `eval-shard.json` of these shard output folders into one table in `--out`,
    /// equal to the unsharded evaluation's (no model runs).
    #[arg(long, num_args = 1.., conflicts_with_all = ["dataset", "root", "shard"])]
    merge: Vec<PathBuf>,
    #[command(flatten)]
    model: ModelArgs,
}

pub fn run(a: EvalArgs) -> anyhow::Result<ExitCode> {
    eval(a).map_err(|e| anyhow::anyhow!(error_line(&e)))
}

/// `eval --merge`: the shards' rows in the data set's order, aggregated as one evaluation.
fn merge(a: &EvalArgs) -> anyhow::Result<ExitCode> {
    let shards = a
        .merge
        .iter()
        .map(|d| dgstereo_eval::shards::ShardResult::read(&d.join("eval-shard.json")))
        .collect::<Result<Vec<_>, _>>()?;
    let table = dgstereo_eval::shards::merge(&shards)?;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| anyhow::anyhow!("{}: cannot create the output folder: {e}", a.out.display()))?;
    println!("{table}");
    let (csv, json) = (a.out.join("eval.csv"), a.out.join("eval.json"));
    table.write_csv(&csv)?;
    table.write_json(&json)?;
    println!(
        "merged {} shard(s), {} sample(s); wrote {} and {}",
        shards.len(),
        table.rows.len(),
        csv.display(),
        json.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// The paper's Table 1 figures beside ours, where the weights are a checkpoint that is one of
/// its rows' models (by name, or by the file name the catalog keeps it under) and `scored`
/// (as the evaluation ran it) one of its data sets.
fn published_lines(a: &EvalArgs, scored: &BenchmarkConfig, table: &dgstereo_eval::EvalTable) -> Vec<String> {
    let Some(weights) = a.model.weights.as_deref().and_then(dgstereo_weights::named_by) else { return Vec::new() };
    let Some(row) = published::table1_row(weights.name) else { return Vec::new() };
    let mut differences = published::protocol_differences(scored);
    differences.extend(a.shard.map(|s| format!("shard {}/{} of the samples", s.index, s.count)));
    published::describe(row, weights.name, &published::compare(row, scored, table), &differences)
}

fn eval(a: EvalArgs) -> anyhow::Result<ExitCode> {
    if !a.merge.is_empty() {
        return merge(&a);
    }
    let start = Instant::now();
    let (Some(dataset_kind), Some(root)) = (a.dataset, a.root.clone()) else {
        bail!("--dataset and --root are required (or --merge)");
    };
    if !root.is_dir() {
        bail!("{}: --root must be the data set's folder", root.display());
    }
    let benchmark = BenchmarkConfig {
        split: a.split,
        weather: a.weather,
        subset: a.subset,
        ..BenchmarkConfig::new(dataset_kind, &root)
    };
    if let Some((key, message)) = benchmark.option_problems().into_iter().next() {
        bail!("--{key}: {message}");
    }
    if dataset_kind == DatasetKind::Middlebury && a.split.is_none() && !middeval3_splits_in(&root).is_empty() {
        bail!("{}: a MiddEval3 folder: choose its split with --split Q, H or F", root.display());
    }
    let dataset = benchmark.load()?;
    if dataset.files.is_empty() {
        bail!("{}: no {} samples found in this folder", root.display(), dataset_kind);
    }
    let without_gt: Vec<&str> =
        dataset.files.iter().filter(|f| f.disparity.is_none()).map(|f| f.name.as_str()).collect();
    if without_gt.len() == dataset.files.len() {
        bail!("{}: no sample has ground truth disparity (is this a test split?)", root.display());
    }
    let total = a.limit.unwrap_or(usize::MAX).min(dataset.len());
    let all: Vec<usize> = (0..total).collect();
    let indices = a.shard.map_or_else(|| all.clone(), |s| s.select(&all));
    let n = indices.len();
    let names: Vec<String> = dataset.files.iter().map(|f| f.name.clone()).collect();
    let protocol = dataset_kind.protocol();
    let (engine, options) = load_engine(&a.model)?;
    eprintln!("configuration: {}", engine.describe(&options));
    std::fs::create_dir_all(&a.out)
        .map_err(|e| anyhow::anyhow!("{}: cannot create the output folder: {e}", a.out.display()))?;
    eprintln!(
        "{:?}: {n} of {} sample(s){}, protocol {}, weights {}, {} iterations{}{}",
        dataset_kind,
        dataset.len(),
        a.shard.map_or(String::new(), |s| format!(" (shard {}/{})", s.index, s.count)),
        protocol.name(),
        engine.weights().display(),
        options.iters,
        match (a.model.max_size, engine.min_size(&options)) {
            (Some(m), _) => format!(", downscaled to at most {m} px (not the benchmark's protocol)"),
            (None, Some(m)) => format!(", pairs under {m} px upscaled to it (--min-size)"),
            (None, None) => String::new(),
        },
        a.model.lr_check.map_or(String::new(), |t| format!(", left-right check at {t} px (--lr-check)"))
    );
    let mut k = 0;
    let result = evaluate_dataset(
        Arc::new(dataset) as Arc<dyn Dataset>,
        indices,
        protocol,
        |sample| engine.predict(&sample.left, &sample.right, &sample.name, &options).map(|p| p.disparity),
        |outcome| {
            k += 1;
            match outcome {
                Ok(row) => {
                    let m = row.all.metrics();
                    eprintln!("[{k}/{n}] {}: epe {:.3}, bad-2 {:.2} %", row.name, m.epe, m.bad_2);
                }
                Err(f) => eprintln!("[{k}/{n}] error: {}: {}", f.name, sample_error(&f.message)),
            }
        },
    );
    println!("{}", result.table);
    let scored = BenchmarkConfig { iters: options.iters, limit: a.limit, max_size: a.model.max_size, ..benchmark };
    for line in published_lines(&a, &scored, &result.table) {
        println!("{line}");
    }
    let (csv, json) = (a.out.join("eval.csv"), a.out.join("eval.json"));
    result.table.write_csv(&csv)?;
    result.table.write_json(&json)?;
    if let Some(shard) = a.shard {
        let stored = dgstereo_eval::shards::ShardResult::new(&result.table, shard, total, |name| {
            names.iter().position(|n| n == name)
        })?;
        stored.write(&a.out.join("eval-shard.json"))?;
    }
    println!(
        "summary: {} of {n} sample(s) scored, {} failed, {:.1} s; wrote {} and {}",
        result.table.rows.len(),
        result.failures.len(),
        start.elapsed().as_secs_f64(),
        csv.display(),
        json.display()
    );
    if result.failures.is_empty() {
        return Ok(ExitCode::SUCCESS);
    }
    eprintln!("failed:");
    for f in &result.failures {
        eprintln!("  {}: {}", f.name, sample_error(&f.message));
    }
    Ok(ExitCode::FAILURE)
}

/// A sample's error on one line, each option field it quotes written as the flag that sets it.
fn sample_error(message: &str) -> String {
    flag_names(message).replace(['\n', '\r'], " ")
}
