//! Our runs in the paper's tables, optionally beside the published figures.
//!
//! [`PaperComparison::new`] fills one of [`PAPER_TABLES`] (the ablation tables) from run results
//! ([`PaperComparison::filled`] any rows, Table 1's among them: [`crate::paper_table1`]): a row takes the
//! scores of the run named by [`PaperRow::run`](crate::paper_tables::PaperRow::run), a column
//! the metric of the benchmark that scores its data set
//! ([`PaperColumn::benchmark`](crate::paper_tables::PaperColumn::benchmark), matched by
//! [`crate::paper_match`]); anything missing stays unknown (NaN, shown as `–`). Design decision:
//! the tables are a pure function of what `dgstereo ablate` scored and of the study's benchmarks,
//! so the same runs always give the same tables, and a partial ablation (some rows trained, some
//! benchmarks present) still fills what it can. With the published figures, each row is three lines: ours, the paper's, and ours minus the
//! paper's (every metric is an error, so a positive difference is worse than published). A row of
//! several seeds shows its mean `± std`, as the ablation table does.

use std::fmt::Write as _;
use std::path::Path;

use dgstereo_core::Result;
use dgstereo_eval::Metrics;
use dgstereo_train::checkpoint::write_atomic;

use crate::paper_match::{BenchmarkMatch, label_for};
use crate::paper_tables::{PAPER_SOURCE, PAPER_TABLES, PaperColumn, PaperTable};

/// A run's results: its name and, per benchmark name, the benchmark's aggregate metrics.
#[derive(Debug, Clone, PartialEq)]
pub struct RunScores {
    /// The run's name (an experiment file's `name`, with a sweep suffix).
    pub run: String,
    /// `(benchmark name, metrics)` for each benchmark the run was scored on (for a row of
    /// several seeds, their mean).
    pub scores: Vec<(String, Metrics)>,
    /// For a row of several seeds, `(benchmark name, standard deviation of each metric)`; empty
    /// for a single run.
    pub spread: Vec<(String, Metrics)>,
}

/// A row of a table as laid out: its label in the paper, the run that fills it and the
/// published figures, one per column.
#[derive(Debug, Clone, PartialEq)]
pub struct ComparedRow {
    /// The row's label in the paper (an ablation's row, or Table 1's method).
    pub label: String,
    /// The run whose scores fill it.
    pub run: String,
    /// The published figures, one per column.
    pub published: Vec<f64>,
}

/// One of the paper's tables filled with our values.
#[derive(Debug, Clone, PartialEq)]
pub struct PaperComparison {
    /// The table's number in the paper.
    pub number: u32,
    /// What the table shows.
    pub title: &'static str,
    /// Where its published figures come from.
    pub source: &'static str,
    /// The columns, in the paper's order.
    pub columns: &'static [PaperColumn],
    /// The rows, each with its published figures.
    pub rows: Vec<ComparedRow>,
    /// Our value per row and column of the table (NaN where unknown).
    pub ours: Vec<Vec<f64>>,
    /// Per row, whether its run is among the results.
    pub found: Vec<bool>,
    /// The standard deviation over seeds per row and column (NaN for a single run).
    pub spread: Vec<Vec<f64>>,
}

impl PaperComparison {
    /// Fills `table` from `runs`, each column from the benchmark `matches` gives its data set
    /// (see the module doc).
    pub fn new(table: &'static PaperTable, runs: &[RunScores], matches: &[BenchmarkMatch]) -> Self {
        let rows = table
            .rows
            .iter()
            .map(|r| ComparedRow { label: r.label.into(), run: r.run.into(), published: r.values.to_vec() })
            .collect();
        Self::filled(table.number, table.title, PAPER_SOURCE, table.columns, rows, runs, matches)
    }

    /// A table of `rows` over `columns`, each row filled from the run of `runs` it names and each
    /// column from the benchmark `matches` gives its data set.
    pub fn filled(
        number: u32,
        title: &'static str,
        source: &'static str,
        columns: &'static [PaperColumn],
        rows: Vec<ComparedRow>,
        runs: &[RunScores],
        matches: &[BenchmarkMatch],
    ) -> Self {
        let mut ours = Vec::with_capacity(rows.len());
        let mut found = Vec::with_capacity(rows.len());
        let mut spread = Vec::with_capacity(rows.len());
        for row in &rows {
            let run = runs.iter().find(|r| r.run == row.run);
            found.push(run.is_some());
            let values = |of: fn(&RunScores) -> &Vec<(String, Metrics)>| -> Vec<f64> {
                columns
                    .iter()
                    .map(|c| {
                        let label = label_for(matches, c.benchmark);
                        run.and_then(|r| of(r).iter().find(|(b, _)| Some(b.as_str()) == label))
                            .and_then(|(_, m)| m.get(c.metric))
                            .unwrap_or(f64::NAN)
                    })
                    .collect()
            };
            ours.push(values(|r| &r.scores));
            spread.push(values(|r| &r.spread));
        }
        Self { number, title, source, columns, rows, ours, found, spread }
    }

    /// Whether any row's run is among the results.
    pub fn has_runs(&self) -> bool {
        self.found.iter().any(|f| *f)
    }

    /// The column headings as the paper writes them: the benchmark before its first metric
    /// (`Midd-H EPE`, `D2`, `DS-Sunny EPE`, `D3`, ...).
    pub fn headings(&self) -> Vec<String> {
        let columns = self.columns;
        columns
            .iter()
            .enumerate()
            .map(|(i, c)| {
                if i == 0 || columns[i - 1].benchmark != c.benchmark {
                    format!("{} {}", c.heading, c.metric_heading)
                } else {
                    c.metric_heading.to_string()
                }
            })
            .collect()
    }

    /// The lines of row `r`: `(source, values)` for ours and, `with_paper`, the paper's and the
    /// difference.
    fn lines(&self, r: usize, with_paper: bool) -> Vec<(&'static str, Vec<f64>)> {
        let mut lines = vec![("ours", self.ours[r].clone())];
        if self.spread[r].iter().any(|v| v.is_finite()) {
            lines.push(("ours std", self.spread[r].clone()));
        }
        if with_paper {
            let paper = &self.rows[r].published;
            lines.push(("paper", paper.clone()));
            lines.push(("difference", self.ours[r].iter().zip(paper).map(|(o, p)| o - p).collect()));
        }
        lines
    }

    /// The table as Markdown, values to the paper's two decimals (see the module doc).
    pub fn to_markdown(&self, with_paper: bool) -> String {
        let mut s = format!("### Table {}: {}\n\n| row | run |", self.number, self.title);
        if with_paper {
            s += " |";
        }
        for h in self.headings() {
            let _ = write!(s, " {h} |");
        }
        s += if with_paper { "\n|---|---|---|" } else { "\n|---|---|" };
        s += &"---:|".repeat(self.columns.len());
        s.push('\n');
        for (r, row) in self.rows.iter().enumerate() {
            let run = if self.found[r] { format!("`{}`", row.run) } else { format!("`{}` (not run)", row.run) };
            let lines = self.lines(r, with_paper).into_iter().filter(|(source, _)| *source != "ours std");
            for (k, (source, values)) in lines.enumerate() {
                s += &if k == 0 { format!("| {} | {run} |", row.label) } else { "| | |".to_string() };
                if with_paper {
                    let _ = write!(s, " {source} |");
                }
                for (c, v) in values.into_iter().enumerate() {
                    let spread = self.spread[r][c];
                    let text = match (v.is_finite(), source) {
                        (false, _) => "–".to_string(),
                        (true, "difference") => format!("{v:+.2}"),
                        (true, "ours") if spread.is_finite() => format!("{v:.2} ± {spread:.2}"),
                        (true, _) => format!("{v:.2}"),
                    };
                    let _ = write!(s, " {text} |");
                }
                s.push('\n');
            }
        }
        if with_paper {
            let _ = write!(s, "\nPublished figures: {}.\n", self.source);
        }
        s
    }

    /// The table as CSV: `row,run,source,<benchmark heading> <metric heading>,...`, one line per
    /// row (`source` = `ours`), an `ours std` line for a row of several seeds and, `with_paper`,
    /// `paper` and `difference` lines; unknown values are empty cells.
    pub fn to_csv(&self, with_paper: bool) -> String {
        let mut s = String::from("row,run,source");
        for c in self.columns {
            let _ = write!(s, ",{} {}", c.heading, c.metric_heading);
        }
        s.push('\n');
        for (r, row) in self.rows.iter().enumerate() {
            for (source, values) in self.lines(r, with_paper) {
                let _ = write!(s, "{},{},{source}", csv_cell(&row.label), csv_cell(&row.run));
                for v in values {
                    s += &match (v.is_finite(), source) {
                        (false, _) => ",".to_string(),
                        (true, "difference") => format!(",{v:.6}"),
                        (true, _) => format!(",{v}"),
                    };
                }
                s.push('\n');
            }
        }
        s
    }
}

fn csv_cell(text: &str) -> String {
    if text.contains([',', '"', '\n']) { format!("\"{}\"", text.replace('"', "\"\"")) } else { text.to_string() }
}

/// The paper's four ablation tables filled from `runs`, in the paper's order, each column from
/// the benchmark `matches` gives its data set
/// ([`match_benchmarks`](crate::paper_match::match_benchmarks)).
pub fn compare_with_paper(runs: &[RunScores], matches: &[BenchmarkMatch]) -> Vec<PaperComparison> {
    PAPER_TABLES.iter().map(|t| PaperComparison::new(t, runs, matches)).collect()
}

/// All tables as one Markdown document, with how ours were matched: rows by run name (Table 1's
/// by the run's network), columns by data set, each column's benchmark listed.
pub fn paper_tables_markdown(tables: &[PaperComparison], matches: &[BenchmarkMatch], with_paper: bool) -> String {
    let mut s = String::from(
        "# The paper's tables\n\nOurs: each row is the run it names (in Table 1, a run whose network \
         is the row's model), each column the \
         `[[benchmarks]]` entry that scores its data set (by data set kind and split or weather, \
         whatever its name), under its protocol (EPE in px; D1/D2/D3 the % of pixels with an error \
         over 1/2/3 px); `–` where the run or the benchmark is missing.\n\nColumns matched:\n\n",
    );
    for m in matches {
        let _ = writeln!(s, "- {}", m.describe());
    }
    for t in tables {
        s.push('\n');
        s += &t.to_markdown(with_paper);
    }
    s
}

/// Writes `paper-tables.md` (every table, and the columns' matches) and `paper-table<N>.csv`
/// (one per table) into `dir`, atomically.
pub fn write_paper_tables(
    tables: &[PaperComparison],
    matches: &[BenchmarkMatch],
    dir: &Path,
    with_paper: bool,
) -> Result<()> {
    write_atomic(&dir.join("paper-tables.md"), paper_tables_markdown(tables, matches, with_paper).as_bytes())?;
    for t in tables {
        let path = dir.join(format!("paper-table{}.csv", t.number));
        write_atomic(&path, t.to_csv(with_paper).as_bytes())?;
    }
    Ok(())
}
