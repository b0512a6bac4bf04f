//! Evaluating a large set in shards: every Nth sample per process, merged into the one table.
//!
//! Design decision: a shard stores its per-image *sums* (pixel counts, error sums, outlier
//! counts), not metrics, with each sample's index in the data set, and the error sum as its bits
//! (JSON's decimal text does not give every f64 back). Merging sorts the rows back into the
//! data set's order and aggregates them as one run would, so the merged table equals the
//! unsharded one exactly: pooled protocols pool the same sums in the same order, per-image ones
//! average the same percentages. Means of shard means are never taken.

use std::path::Path;

use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::metrics::MetricSums;
use crate::protocol::Protocol;
use crate::table::{EvalRow, EvalTable};

/// Shard `index` of `count` (`--shard 1/4` is index 1 of 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which shard, `0..count`.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let bad = || Error::config("shard", format!("'{s}': expected I/N with 0 <= I < N (0/4 is the first of four)"));
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) =
            (i.trim().parse::<usize>().map_err(|_| bad())?, n.trim().parse::<usize>().map_err(|_| bad())?);
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

impl Shard {
    /// The data set indices of this shard among `indices`: every `count`th, from `index`.
    pub fn select(&self, indices: &[usize]) -> Vec<usize> {
        indices.iter().skip(self.index).step_by(self.count).copied().collect()
    }
}

/// [`MetricSums`] with the error sum as its bits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct StoredSums {
    valid_pixels: u64,
    abs_error_bits: u64,
    bad: [u64; 5],
    d1: u64,
}

impl From<MetricSums> for StoredSums {
    fn from(s: MetricSums) -> Self {
        Self { valid_pixels: s.valid_pixels, abs_error_bits: s.abs_error.to_bits(), bad: s.bad, d1: s.d1 }
    }
}

impl From<StoredSums> for MetricSums {
    fn from(s: StoredSums) -> Self {
        Self { valid_pixels: s.valid_pixels, abs_error: f64::from_bits(s.abs_error_bits), bad: s.bad, d1: s.d1 }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct StoredRow {
    index: usize,
    name: String,
    group: Option<String>,
    all: StoredSums,
    noc: Option<StoredSums>,
}

/// What one shard scored (`eval-shard.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardResult {
    /// The protocol the rows were scored under.
    pub protocol: Protocol,
    /// Which shard.
    pub shard: Shard,
    /// How many samples the whole evaluation has.
    pub total: usize,
    rows: Vec<StoredRow>,
}

impl ShardResult {
    /// The rows of `table` with their data set indices (`index_of` finds a row's index by name).
    pub fn new(
        table: &EvalTable,
        shard: Shard,
        total: usize,
        index_of: impl Fn(&str) -> Option<usize>,
    ) -> Result<Self> {
        let rows = table
            .rows
            .iter()
            .map(|r| {
                let index = index_of(&r.name).ok_or_else(|| Error::sample(&r.name, "not in the data set"))?;
                Ok(StoredRow {
                    index,
                    name: r.name.clone(),
                    group: r.group.clone(),
                    all: r.all.into(),
                    noc: r.noc.map(Into::into),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { protocol: table.protocol, shard, total, rows })
    }

    /// Writes the result to `path` (JSON).
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| Error::format(path, e.to_string()))?;
        std::fs::write(path, text + "\n").map_err(|e| Error::io(path, e))
    }

    /// Reads a result written by [`ShardResult::write`].
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        serde_json::from_str(&text).map_err(|e| Error::format(path, format!("not a shard result: {e}")))
    }
}

/// The table of all shards, in the data set's order. Every shard of one evaluation must be there
/// once: same protocol, same shard count and total, each index `0..count` present.
pub fn merge(shards: &[ShardResult]) -> Result<EvalTable> {
    let first = shards.first().ok_or_else(|| Error::mismatch("shards", "none given: no shard to merge"))?;
    let count = first.shard.count;
    for s in shards {
        if s.protocol != first.protocol || s.shard.count != count || s.total != first.total {
            return Err(Error::mismatch(
                format!("shard {}/{} ({:?}, {} samples)", s.shard.index, s.shard.count, s.protocol, s.total),
                format!(
                    "not of the evaluation of shard {}/{count} ({:?}, {} samples)",
                    first.shard.index, first.protocol, first.total
                ),
            ));
        }
    }
    let mut present: Vec<usize> = shards.iter().map(|s| s.shard.index).collect();
    present.sort_unstable();
    if present != (0..count).collect::<Vec<_>>() {
        return Err(Error::mismatch(format!("shards {present:?}"), format!("all of 0..{count} are needed once each")));
    }
    let mut rows: Vec<&StoredRow> = shards.iter().flat_map(|s| &s.rows).collect();
    rows.sort_by_key(|r| r.index);
    let mut table = EvalTable::new(first.protocol);
    for r in rows {
        table.push(EvalRow {
            name: r.name.clone(),
            group: r.group.clone(),
            all: r.all.into(),
            noc: r.noc.map(Into::into),
        });
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, abs_error: f64, valid: u64) -> EvalRow {
        EvalRow {
            name: name.into(),
            group: None,
            all: MetricSums { valid_pixels: valid, abs_error, bad: [valid, 3, 2, 1, 0], d1: 1 },
            noc: None,
        }
    }

    #[test]
    fn shards_merge_into_exactly_the_unsharded_table() {
        let names = ["a", "b", "c", "d", "e"];
        let rows: Vec<EvalRow> =
            names.iter().enumerate().map(|(i, n)| row(n, 0.1 * (i as f64 + 1.0) / 3.0, 10 + i as u64)).collect();
        for protocol in [Protocol::Kitti, Protocol::Middlebury] {
            let mut whole = EvalTable::new(protocol);
            rows.iter().cloned().for_each(|r| whole.push(r));
            let results: Vec<ShardResult> = (0..2)
                .map(|i| {
                    let shard = Shard { index: i, count: 2 };
                    let mut part = EvalTable::new(protocol);
                    for k in shard.select(&[0, 1, 2, 3, 4]) {
                        part.push(rows[k].clone());
                    }
                    let result = ShardResult::new(&part, shard, 5, |n| names.iter().position(|x| *x == n)).unwrap();
                    let text = serde_json::to_string(&result).unwrap();
                    serde_json::from_str(&text).unwrap()
                })
                .collect();
            let merged = merge(&[results[1].clone(), results[0].clone()]).unwrap();
            assert_eq!(merged, whole);
            assert_eq!(merged.to_csv(), whole.to_csv());
            let e = merge(&results[..1]).unwrap_err().to_string();
            assert!(e.contains("0..2"), "{e}");
        }
        assert_eq!("1/4".parse::<Shard>().unwrap(), Shard { index: 1, count: 4 });
        assert!("4/4".parse::<Shard>().is_err() && "x".parse::<Shard>().is_err());
    }
}
