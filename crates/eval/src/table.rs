//! Evaluation tables: one row per image (all valid pixels and, where an occlusion mask exists,
//! non-occluded pixels), aggregate rows per the protocol, written as CSV, JSON or a text table.

use std::fmt;
use std::path::Path;

use serde_json::json;

use dgstereo_core::{Error, Result};

use crate::metrics::{METRIC_NAMES, MetricSums, Metrics};
use crate::protocol::Protocol;

/// One image's result.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalRow {
    /// Sample name.
    pub name: String,
    /// Group (DrivingStereo weather, scene, ...), if any.
    pub group: Option<String>,
    /// Sums over all valid pixels.
    pub all: MetricSums,
    /// Sums over valid non-occluded pixels, where an occlusion mask exists.
    pub noc: Option<MetricSums>,
}

/// An aggregate row: its label (`all` or a group name) and metrics.
#[derive(Clone, Debug, PartialEq)]
pub struct AggregateRow {
    /// `all`, or the group name.
    pub label: String,
    /// Number of images.
    pub images: usize,
    /// Aggregate over all valid pixels.
    pub all: Metrics,
    /// Aggregate over non-occluded pixels (images that have them).
    pub noc: Option<Metrics>,
}

/// Per-image rows plus aggregates under a protocol.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalTable {
    /// How rows are aggregated.
    pub protocol: Protocol,
    /// Per-image rows, in insertion order.
    pub rows: Vec<EvalRow>,
}

impl EvalTable {
    /// An empty table.
    pub fn new(protocol: Protocol) -> Self {
        Self { protocol, rows: Vec::new() }
    }

    /// Adds a row.
    pub fn push(&mut self, row: EvalRow) {
        self.rows.push(row);
    }

    fn aggregate_rows(&self, label: &str, rows: &[&EvalRow]) -> AggregateRow {
        let all: Vec<MetricSums> = rows.iter().map(|r| r.all).collect();
        let noc: Vec<MetricSums> = rows.iter().filter_map(|r| r.noc).collect();
        AggregateRow {
            label: label.to_string(),
            images: rows.len(),
            all: self.protocol.aggregate(&all),
            noc: (!noc.is_empty()).then(|| self.protocol.aggregate(&noc)),
        }
    }

    /// The aggregate rows: `all` first, then one per group (in order of first appearance).
    pub fn aggregates(&self) -> Vec<AggregateRow> {
        let every: Vec<&EvalRow> = self.rows.iter().collect();
        let mut out = vec![self.aggregate_rows("all", &every)];
        let mut groups: Vec<&str> = Vec::new();
        for r in &self.rows {
            if let Some(g) = r.group.as_deref()
                && !groups.contains(&g)
            {
                groups.push(g);
            }
        }
        for g in groups {
            let rows: Vec<&EvalRow> = self.rows.iter().filter(|r| r.group.as_deref() == Some(g)).collect();
            out.push(self.aggregate_rows(g, &rows));
        }
        out
    }

    fn has_noc(&self) -> bool {
        self.rows.iter().any(|r| r.noc.is_some())
    }

    fn header(&self) -> Vec<String> {
        let mut h = vec!["name".to_string(), "group".into(), "valid_pixels".into()];
        h.extend(METRIC_NAMES.iter().map(|s| s.to_string()));
        if self.has_noc() {
            h.push("noc-valid_pixels".into());
            h.extend(METRIC_NAMES.iter().map(|s| format!("noc-{s}")));
        }
        h
    }

    fn cells(
        &self,
        name: &str,
        group: &str,
        all: &Metrics,
        noc: Option<&Metrics>,
        fmt_num: fn(f64) -> String,
    ) -> Vec<String> {
        let mut c = vec![name.to_string(), group.to_string(), all.valid_pixels.to_string()];
        c.extend(all.values().iter().map(|v| fmt_num(*v)));
        if self.has_noc() {
            match noc {
                Some(n) => {
                    c.push(n.valid_pixels.to_string());
                    c.extend(n.values().iter().map(|v| fmt_num(*v)));
                }
                None => c.extend(std::iter::repeat_n(String::new(), 8)),
            }
        }
        c
    }

    /// CSV text: a header, one line per image, then the aggregate rows (name `mean:<label>`).
    /// Columns: `name,group,valid_pixels,epe,bad-0.5,...,d1-all` and, where any row has
    /// non-occluded results, the same prefixed `noc-`. NaN is written as an empty cell.
    pub fn to_csv(&self) -> String {
        let num = |v: f64| {
            if v.is_finite() { format!("{v:.6}") } else { String::new() }
        };
        let mut out = self.header().join(",") + "\n";
        for r in &self.rows {
            let noc = r.noc.map(|s| s.metrics());
            let cells = self.cells(
                &csv_escape(&r.name),
                &csv_escape(r.group.as_deref().unwrap_or("")),
                &r.all.metrics(),
                noc.as_ref(),
                num,
            );
            out += &(cells.join(",") + "\n");
        }
        for a in self.aggregates() {
            let cells = self.cells(&csv_escape(&format!("mean:{}", a.label)), "", &a.all, a.noc.as_ref(), num);
            out += &(cells.join(",") + "\n");
        }
        out
    }

    /// The table as JSON: `{"protocol", "aggregation", "headline", "rows": [{"name", "group",
    /// "all": {metrics}, "noc": {metrics}|null}], "aggregates": [{"label", "images", "all", "noc"}]}`.
    pub fn to_json(&self) -> serde_json::Value {
        let rows: Vec<_> = self
            .rows
            .iter()
            .map(|r| {
                json!({
                    "name": r.name,
                    "group": r.group,
                    "all": r.all.metrics().to_json(),
                    "noc": r.noc.map(|s| s.metrics().to_json()),
                })
            })
            .collect();
        let aggs: Vec<_> = self
            .aggregates()
            .iter()
            .map(|a| json!({"label": a.label, "images": a.images, "all": a.all.to_json(), "noc": a.noc.map(|m| m.to_json())}))
            .collect();
        json!({
            "protocol": self.protocol.name(),
            "aggregation": format!("{:?}", self.protocol.aggregation()),
            "headline": self.protocol.headline(),
            "rows": rows,
            "aggregates": aggs,
        })
    }

    /// Writes [`EvalTable::to_csv`] to `path`.
    pub fn write_csv(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_csv()).map_err(|e| Error::io(path, e))
    }

    /// Writes [`EvalTable::to_json`] (pretty) to `path`.
    pub fn write_json(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(&self.to_json()).map_err(|e| Error::format(path, e.to_string()))?;
        std::fs::write(path, text + "\n").map_err(|e| Error::io(path, e))
    }
}

fn csv_escape(s: &str) -> String {
    if s.contains([',', '"', '\n']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

/// A fixed-width text table: per-image rows, a rule, aggregate rows.
impl fmt::Display for EvalTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let num = |v: f64| {
            if v.is_finite() { format!("{v:.3}") } else { "-".to_string() }
        };
        let header = self.header();
        let mut lines: Vec<Vec<String>> = self
            .rows
            .iter()
            .map(|r| {
                let noc = r.noc.map(|s| s.metrics());
                self.cells(&r.name, r.group.as_deref().unwrap_or(""), &r.all.metrics(), noc.as_ref(), num)
            })
            .collect();
        let n_rows = lines.len();
        for a in self.aggregates() {
            lines.push(self.cells(&format!("mean:{}", a.label), "", &a.all, a.noc.as_ref(), num));
        }
        let widths: Vec<usize> = (0..header.len())
            .map(|i| lines.iter().map(|l| l[i].len()).chain([header[i].len()]).max().unwrap_or(0))
            .collect();
        let fmt_line = |cells: &[String]| -> String {
            cells
                .iter()
                .enumerate()
                .map(|(i, c)| if i < 2 { format!("{c:<w$}", w = widths[i]) } else { format!("{c:>w$}", w = widths[i]) })
                .collect::<Vec<_>>()
                .join("  ")
        };
        writeln!(
            f,
            "protocol: {} ({:?}; headline {})",
            self.protocol.name(),
            self.protocol.aggregation(),
            self.protocol.headline().join(", ")
        )?;
        writeln!(f, "{}", fmt_line(&header))?;
        for (i, l) in lines.iter().enumerate() {
            if i == n_rows {
                writeln!(f, "{}", "-".repeat(widths.iter().sum::<usize>() + 2 * (widths.len() - 1)))?;
            }
            writeln!(f, "{}", fmt_line(l))?;
        }
        Ok(())
    }
}
