//! The published figures of the paper's ablation tables, kept as data beside the code that lays
//! our runs out in the same tables ([`crate::paper_report`]).
//!
//! Source: Lin et al., "Rethinking Monocular Depth Embedding for Generalized Stereo Matching",
//! Tables 2 to 5 (copied from `shared/reference/paper-tables.md`, which transcribes them). Every
//! model there is trained on SceneFlow only and evaluated zero-shot with 32 GRU iterations; EPE in
//! pixels, D1/D2/D3 the percentage of pixels whose error exceeds 1/2/3 px. The columns are the
//! paper's, in its order; each names the data set it scores ([`PaperBenchmark`], the one of
//! `dgstereo_eval::published`: a data set kind and its split or weather, which a study's
//! `[[benchmarks]]` entry scoring it alone matches whatever its name) and
//! the metric of `dgstereo_eval` it is ([`PaperColumn`]), and each row names the run of
//! `experiments/` that trains it ([`PaperRow::run`]). Rows that the paper repeats across tables
//! are one run: Table 3's Depth+DCN+both is Table 2's +DGIA, Table 4's Gradient-Guided is Table
//! 2's +DGIA +gradient-GRU. Table 5's header labels every metric "D1"; its tau = 0.9 row is the
//! paper's model with Table 1's D2/D3/D1 within rounding, so the columns are Table 1's.

use dgstereo_data::datasets::DrivingStereoWeather;
pub use dgstereo_eval::published::PaperBenchmark;

/// Where the figures come from, for the tables' captions.
pub const PAPER_SOURCE: &str =
    "Lin et al., \"Rethinking Monocular Depth Embedding for Generalized Stereo Matching\", Tables 2-5";

/// A column of a table: a benchmark and one of its metrics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PaperColumn {
    /// The data set it scores.
    pub benchmark: PaperBenchmark,
    /// The metric's name in `dgstereo_eval::METRIC_NAMES` (`epe`, `bad-1`, `bad-2`, `bad-3`).
    pub metric: &'static str,
    /// The benchmark's heading in the paper (`Midd-H`, `DS-Sunny`, ...).
    pub heading: &'static str,
    /// The metric's heading in the paper (`EPE`, `D1`, `D2`, `D3`).
    pub metric_heading: &'static str,
}

/// A row of a table: its label in the paper, the run that reproduces it and the figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperRow {
    /// The row's label in the paper.
    pub label: &'static str,
    /// The name of the run of `experiments/` that trains the row's model.
    pub run: &'static str,
    /// The published figures, one per column.
    pub values: &'static [f64],
}

/// One of the paper's ablation tables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperTable {
    /// The table's number in the paper (2 to 5).
    pub number: u32,
    /// What the table ablates.
    pub title: &'static str,
    /// The columns, in the paper's order.
    pub columns: &'static [PaperColumn],
    /// The rows, in the paper's order.
    pub rows: &'static [PaperRow],
}

/// The EPE column of `benchmark` (headings from [`PaperBenchmark::heading`]).
const fn epe(benchmark: PaperBenchmark) -> PaperColumn {
    PaperColumn { benchmark, metric: "epe", heading: benchmark.heading(), metric_heading: "EPE" }
}

/// The column of the bad-pixel rate the paper reports for `benchmark` ([`PaperBenchmark::rate`]).
const fn rate(benchmark: PaperBenchmark) -> PaperColumn {
    let (metric, metric_heading) = benchmark.rate();
    PaperColumn { benchmark, metric, heading: benchmark.heading(), metric_heading }
}

const fn row(label: &'static str, run: &'static str, values: &'static [f64]) -> PaperRow {
    PaperRow { label, run, values }
}

const DS_SUNNY: PaperBenchmark = PaperBenchmark::DrivingStereo(DrivingStereoWeather::Sunny);
const DS_CLOUDY: PaperBenchmark = PaperBenchmark::DrivingStereo(DrivingStereoWeather::Cloudy);
const DS_FOGGY: PaperBenchmark = PaperBenchmark::DrivingStereo(DrivingStereoWeather::Foggy);
const DS_RAINY: PaperBenchmark = PaperBenchmark::DrivingStereo(DrivingStereoWeather::Rainy);

/// Table 2's columns: the four DrivingStereo weathers, EPE and D3 each.
pub const DRIVINGSTEREO_COLUMNS: [PaperColumn; 8] = [
    epe(DS_SUNNY),
    rate(DS_SUNNY),
    epe(DS_CLOUDY),
    rate(DS_CLOUDY),
    epe(DS_FOGGY),
    rate(DS_FOGGY),
    epe(DS_RAINY),
    rate(DS_RAINY),
];

/// The seven benchmarks of Tables 1, 3, 4 and 5, EPE and the benchmark's rate each.
pub const GENERALISATION_COLUMNS: [PaperColumn; 14] = [
    epe(PaperBenchmark::MiddleburyH),
    rate(PaperBenchmark::MiddleburyH),
    DRIVINGSTEREO_COLUMNS[0],
    DRIVINGSTEREO_COLUMNS[1],
    DRIVINGSTEREO_COLUMNS[2],
    DRIVINGSTEREO_COLUMNS[3],
    DRIVINGSTEREO_COLUMNS[4],
    DRIVINGSTEREO_COLUMNS[5],
    DRIVINGSTEREO_COLUMNS[6],
    DRIVINGSTEREO_COLUMNS[7],
    epe(PaperBenchmark::Kitti2015),
    rate(PaperBenchmark::Kitti2015),
    epe(PaperBenchmark::Eth3d),
    rate(PaperBenchmark::Eth3d),
];

/// The run names of the ablation tables' rows, each once, in the tables' order: the runs a
/// study names to fill them.
pub fn paper_run_names() -> Vec<&'static str> {
    let mut names: Vec<&'static str> = Vec::new();
    for row in PAPER_TABLES.iter().flat_map(|t| t.rows) {
        if !names.contains(&row.run) {
            names.push(row.run);
        }
    }
    names
}

/// The paper's four ablation tables, in its order.
pub const PAPER_TABLES: [PaperTable; 4] = [
    PaperTable {
        number: 2,
        title: "the components (DrivingStereo only)",
        columns: &DRIVINGSTEREO_COLUMNS,
        rows: &[
            row("Baseline", "baseline", &[1.81, 8.34, 1.68, 8.85, 1.83, 12.73, 3.79, 32.36]),
            row("+DGIA", "+dgia", &[1.82, 8.58, 1.64, 8.25, 1.74, 11.18, 2.79, 28.37]),
            row("+DGIA +gradient-GRU", "+dgia+gradient", &[1.72, 7.96, 1.57, 7.91, 1.69, 10.77, 2.61, 29.13]),
            row("+DGIA +gradient-GRU +EALS", "paper", &[1.60, 6.81, 1.51, 6.63, 1.63, 9.31, 2.50, 26.76]),
        ],
    },
    PaperTable {
        number: 3,
        title: "DGIA's fusion",
        columns: &GENERALISATION_COLUMNS,
        rows: &[
            row(
                "Depth+CNN+both",
                "depth-cnn-both",
                &[1.47, 9.35, 1.68, 8.32, 1.63, 9.05, 1.76, 12.37, 2.76, 29.70, 1.05, 5.24, 0.22, 2.41],
            ),
            row(
                "Depth+DCN+only (context)",
                "depth-dcn-context-only",
                &[1.53, 9.49, 1.85, 8.57, 1.67, 8.76, 1.76, 12.14, 2.68, 29.31, 1.11, 5.57, 0.22, 1.81],
            ),
            row(
                "Depth+DCN+both",
                "+dgia",
                &[0.99, 7.55, 1.82, 8.58, 1.64, 8.25, 1.74, 11.18, 2.79, 28.37, 1.02, 4.87, 0.21, 1.75],
            ),
        ],
    },
    PaperTable {
        number: 4,
        title: "the GRU's guidance",
        columns: &GENERALISATION_COLUMNS,
        rows: &[
            row(
                "Depth-Guided",
                "depth-guided-gru",
                &[1.15, 8.28, 1.80, 8.35, 1.60, 8.29, 1.72, 11.32, 2.72, 29.13, 1.03, 5.01, 0.21, 1.95],
            ),
            row(
                "Gradient-Guided",
                "+dgia+gradient",
                &[1.07, 8.19, 1.72, 7.96, 1.57, 7.91, 1.69, 10.77, 2.61, 29.13, 1.03, 5.15, 0.21, 1.97],
            ),
        ],
    },
    PaperTable {
        number: 5,
        title: "EALS's threshold tau",
        columns: &GENERALISATION_COLUMNS,
        rows: &[
            row(
                "τ = 0.8",
                "tau-sweep/loss.tau=0.8",
                &[1.61, 9.72, 1.63, 6.90, 1.53, 6.96, 1.66, 9.82, 2.56, 27.34, 1.03, 4.83, 0.22, 1.91],
            ),
            row(
                "τ = 0.9",
                "tau-sweep/loss.tau=0.9",
                &[1.00, 7.21, 1.60, 6.81, 1.51, 6.63, 1.63, 9.31, 2.50, 26.76, 1.00, 4.61, 0.22, 1.81],
            ),
            row(
                "τ = 1.0",
                "tau-sweep/loss.tau=1.0",
                &[1.09, 8.66, 1.62, 6.96, 1.55, 7.44, 1.69, 10.78, 2.63, 28.76, 1.01, 4.65, 0.22, 1.86],
            ),
        ],
    },
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_run_name_is_listed_once_in_table_order() {
        let names = paper_run_names();
        assert_eq!(names[..2], ["baseline", "+dgia"]);
        assert_eq!(names.iter().filter(|n| **n == "+dgia").count(), 1, "{names:?}");
        assert_eq!(names.len(), 10, "{names:?}");
    }
}
