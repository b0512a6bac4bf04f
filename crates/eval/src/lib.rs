//! Evaluation for dgstereo: disparity metrics, benchmark protocols and result tables.
//!
//! [`metrics`] scores one prediction against ground truth on valid pixels into additive
//! [`MetricSums`] (so images can be pooled) and [`Metrics`] with unambiguous names (`epe`,
//! `bad-0.5` … `bad-4`, `d1-all`). [`protocol`] states, per benchmark, which pixels count and how
//! images are aggregated (pooled or mean of per-image rates), following RAFT-Stereo's evaluation.
//! [`table`] collects per-image rows into an [`EvalTable`] with aggregate rows, written as CSV,
//! JSON or text. [`files`] is the file-level entry point behind `dgstereo metrics`, and
//! [`driver`] scores a predictor over a whole data set (behind `dgstereo eval`); [`benchmark`]
//! names the data sets and their protocols for the eval command and experiment files.
//! [`published`] holds the paper's Table 1 (zero-shot figures of the models trained on SceneFlow
//! only), which `eval` of such a model prints beside ours.
#![deny(missing_docs)]

pub mod benchmark;
pub mod driver;
pub mod files;
pub mod metrics;
pub mod protocol;
pub mod published;
pub mod shards;
pub mod table;

pub use benchmark::{BenchmarkConfig, DatasetKind};
pub use driver::{DatasetEvaluation, SampleFailure, evaluate_dataset, score_sample};
pub use files::{metrics_for_files, metrics_json};
pub use metrics::{BAD_THRESHOLDS, METRIC_NAMES, MetricSums, Metrics, ValidOptions, accumulate, evaluate};
pub use protocol::{Aggregation, Protocol};
pub use table::{AggregateRow, EvalRow, EvalTable};
