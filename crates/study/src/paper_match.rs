//! Which benchmark of a study fills which column of the paper's tables.
//!
//! Design decision: a column is matched by what a benchmark scores, never by what it is called.
//! Each of the paper's data sets is a [`PaperBenchmark`] (a data set kind and its split or
//! weather); the first `[[benchmarks]]` entry of the study that scores it fills its columns, so a
//! folder benchmark named `drivingstereo-sunny` stays out of the DrivingStereo column. The
//! paper's figures are zero-shot, with 32 iterations, on every sample at full size: a matched
//! benchmark scored otherwise (other iterations, a `limit`, a `max_size`) still fills the column,
//! and its match says how it differs, so nobody reads a smoke figure as the paper's protocol.

use dgstereo_eval::BenchmarkConfig;

use crate::paper_tables::{PAPER_TABLES, PaperBenchmark};

/// The iterations of every figure of the paper's tables.
pub const PAPER_ITERATIONS: usize = 32;

/// One of the paper's data sets and the study's benchmark that scores it, if any.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchmarkMatch {
    /// The paper's data set.
    pub wanted: PaperBenchmark,
    /// Its heading in the paper (`DS-Sunny`).
    pub heading: &'static str,
    /// The first benchmark of the study that scores it.
    pub found: Option<BenchmarkConfig>,
}

impl BenchmarkMatch {
    /// The label of the matched benchmark (the key of its scores).
    pub fn label(&self) -> Option<&str> {
        self.found.as_ref().map(BenchmarkConfig::label)
    }

    /// How the matched benchmark is scored otherwise than the paper's figures.
    pub fn differences(&self) -> Vec<String> {
        let Some(b) = &self.found else { return Vec::new() };
        let mut d = Vec::new();
        if b.iters != PAPER_ITERATIONS {
            d.push(format!("{} iterations (the paper: {PAPER_ITERATIONS})", b.iters));
        }
        d.extend(b.limit.map(|n| format!("only the first {n} samples")));
        d.extend(b.max_size.map(|m| format!("pairs downscaled to at most {m} px")));
        d
    }

    /// The match in one line: `DS-Sunny: benchmark 'ds' (drivingstereo at /x, weather sunny, 32
    /// iterations)`, with how it differs from the paper's protocol, or that no benchmark of the
    /// study scores the data set and the keys that would.
    pub fn describe(&self) -> String {
        match &self.found {
            None => format!("{}: no benchmark of the study ({})", self.heading, self.wanted.keys()),
            Some(b) => {
                let mut line = format!("{}: benchmark '{}' ({})", self.heading, b.label(), b.settings());
                let differences = self.differences();
                if !differences.is_empty() {
                    line += &format!("; not the paper's protocol: {}", differences.join(", "));
                }
                line
            }
        }
    }
}

/// For each data set of the paper's tables (in the order the tables first name them), the first
/// of `benchmarks` that scores it alone ([`PaperBenchmark::matches_alone`]: a DrivingStereo
/// benchmark of all weathers stores one aggregate, which is no weather's column).
pub fn match_benchmarks(benchmarks: &[BenchmarkConfig]) -> Vec<BenchmarkMatch> {
    let mut matches: Vec<BenchmarkMatch> = Vec::new();
    for column in PAPER_TABLES.iter().flat_map(|t| t.columns) {
        if matches.iter().any(|m| m.wanted == column.benchmark) {
            continue;
        }
        matches.push(BenchmarkMatch {
            wanted: column.benchmark,
            heading: column.heading,
            found: benchmarks.iter().find(|b| column.benchmark.matches_alone(b)).cloned(),
        });
    }
    matches
}

/// The label of the benchmark that fills the columns of data set `wanted`, if any.
pub fn label_for(matches: &[BenchmarkMatch], wanted: PaperBenchmark) -> Option<&str> {
    matches.iter().find(|m| m.wanted == wanted).and_then(BenchmarkMatch::label)
}
