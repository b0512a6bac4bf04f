//! Studies of many runs: an ablation trains every run of some experiment files, each into a
//! folder of its own, scores each finished model, and lays the scores out in the ablation table
//! and the paper's tables.
//!
//! Design decision: the study is a library the binary calls, and its only state is on disk. Each
//! run is one [`task`]: checked before anything trains ([`task::check_run`]), trained by the
//! caller (who draws its progress), scored into its own folder ([`scores`]); the tables are built
//! from those folders alone ([`mod@collect`]), so a study run locally and one run as a Slurm array
//! ([`slurm`]: a task per run, then a collecting job) write the same bytes, and a study stopped
//! anywhere continues where it stopped. [`record`] is what the folders record (the study itself
//! in `study.json`, how far each run got), [`runs`] names the folders. The tables:
//! [`ablation_table`] (seeds folded into a row, a best row marked only beyond their spread),
//! [`ablation_plot`] (every row's validation curve), and the paper's layout ([`paper_tables`],
//! its published figures; [`paper_match`], which benchmark fills which of its columns;
//! [`paper_report`], our rows beside its figures; [`paper_table1`], the runs of Table 1's models
//! laid out as Table 1, by their networks). The library never prints: what a caller shows
//! comes back as values or through a callback.
#![deny(missing_docs)]

pub mod ablation_plot;
pub mod ablation_table;
pub mod collect;
pub mod paper_match;
pub mod paper_report;
pub mod paper_table1;
pub mod paper_tables;
pub mod record;
pub mod runs;
pub mod scores;
pub mod scoring;
pub mod slurm;
pub mod task;

pub use collect::{Collected, collect, collect_study};
pub use record::Study;
pub use runs::{check_distinct_folders, folder_name, parts_of, run_folder};
