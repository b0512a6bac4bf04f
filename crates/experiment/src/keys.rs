//! Dotted keys of TOML tables, which file set each key, and deserialisation whose errors name
//! the file and the key.
//!
//! A merged table has lost the positions of its values, so serde's errors could name a field but
//! neither its table nor its file. [`deserialize`] therefore writes the merged table as TOML with
//! one fully dotted key per line (`"loss"."tau" = 0.9`): the position of a deserialisation error
//! then gives the line, the line gives the dotted key, and the [`Provenance`] gives the file that
//! set it. A second pass compares the input with the configuration serialised back, which finds
//! any key that deserialisation accepted but did not keep.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Problem, Result};
use toml::{Table, Value};

use crate::ExperimentConfig;

/// For each dotted key, the file that last set it (leaves and empty tables).
pub type Provenance = BTreeMap<String, PathBuf>;

/// The dotted form of a key path (`["loss", "tau"]` → `loss.tau`).
pub fn dotted(path: &[String]) -> String {
    path.join(".")
}

/// The segments of a dotted key (`loss.tau` → `["loss", "tau"]`).
pub fn split(key: &str) -> Vec<String> {
    key.split('.').map(str::to_string).collect()
}

/// Every leaf of `table` (a non-table value, or an empty table) with its key path.
pub fn leaves(table: &Table) -> Vec<(Vec<String>, Value)> {
    fn walk(table: &Table, prefix: &mut Vec<String>, out: &mut Vec<(Vec<String>, Value)>) {
        for (key, value) in table {
            prefix.push(key.clone());
            match value {
                Value::Table(inner) if !inner.is_empty() => walk(inner, prefix, out),
                other => out.push((prefix.clone(), other.clone())),
            }
            prefix.pop();
        }
    }
    let mut out = Vec::new();
    walk(table, &mut Vec::new(), &mut out);
    out
}

/// The value at `path`, if every step exists.
pub fn get<'a>(table: &'a Table, path: &[String]) -> Option<&'a Value> {
    let (first, rest) = path.split_first()?;
    let value = table.get(first)?;
    if rest.is_empty() {
        return Some(value);
    }
    match value {
        Value::Table(inner) => get(inner, rest),
        _ => None,
    }
}

/// Sets the value at `path`, creating missing tables on the way.
///
/// # Errors
/// A [`Problem`] keyed by the dotted prefix that holds a value other than a table (or by the
/// empty key when `path` is empty).
pub fn set(table: &mut Table, path: &[String], value: Value) -> std::result::Result<(), Problem> {
    let Some((first, rest)) = path.split_first() else {
        return Err(Problem::new("", "an empty key"));
    };
    if rest.is_empty() {
        table.insert(first.clone(), value);
        return Ok(());
    }
    let entry = table.entry(first.clone()).or_insert_with(|| Value::Table(Table::new()));
    match entry {
        Value::Table(inner) => set(inner, rest, value).map_err(|p| p.within(first)),
        _ => Err(Problem::new(first.clone(), "is a value, not a table")),
    }
}

/// The file that set `key` or, failing that, the nearest enclosing table or contained key that
/// has one; `fallback` when the key comes from the defaults.
pub fn file_of(provenance: &Provenance, key: &str, fallback: &Path) -> PathBuf {
    let mut prefix = key;
    loop {
        if let Some(file) = provenance.get(prefix) {
            return file.clone();
        }
        let below = format!("{prefix}.");
        if let Some((_, file)) = provenance.range(below.clone()..).next().filter(|(k, _)| k.starts_with(&below)) {
            return file.clone();
        }
        match prefix.rfind('.') {
            Some(i) => prefix = &prefix[..i],
            None => return fallback.to_path_buf(),
        }
    }
}

/// Deserialises a merged table; errors name the file that set the offending key, and the key.
///
/// # Errors
/// [`Error::Format`] for unknown keys, missing keys, and values of the wrong type or range.
pub fn deserialize(table: &Table, provenance: &Provenance, fallback: &Path) -> Result<ExperimentConfig> {
    let lines = leaves(table);
    let mut text = String::new();
    let mut line_starts = Vec::with_capacity(lines.len());
    for (path, value) in &lines {
        line_starts.push(text.len());
        let key: Vec<String> = path.iter().map(|k| Value::String(k.clone()).to_string()).collect();
        text += &format!("{} = {}\n", key.join("."), value);
    }
    let config: ExperimentConfig = toml::from_str(&text).map_err(|e| {
        let line = e.span().map(|span| line_starts.partition_point(|&start| start <= span.start).saturating_sub(1));
        let located = line.and_then(|i| lines.get(i)).map(|(path, _)| dotted(path));
        let key = refine_key(e.message(), located.as_deref(), &lines);
        let file = file_of(provenance, &key, fallback);
        let key = if key.is_empty() { "(top level)".to_string() } else { key };
        Error::format(file, format!("{key}: {}", e.message()))
    })?;
    let written = Value::try_from(&config)
        .map_err(|e| Error::format(fallback, format!("cannot serialise the configuration: {e}")))?;
    if let Value::Table(written) = written
        && let Some(key) = unused_key(table, &written, &mut Vec::new())
    {
        let file = file_of(provenance, &key, fallback);
        return Err(Error::format(file, format!("{key}: unknown key (not read by this configuration)")));
    }
    Ok(config)
}

/// The most precise key for a serde message: the line's key, or for `unknown field` /
/// `missing field` messages the field under the table of that line.
fn refine_key(message: &str, located: Option<&str>, lines: &[(Vec<String>, Value)]) -> String {
    let field = |prefix: &str| message.strip_prefix(prefix).and_then(|rest| rest.split('`').next()).map(str::to_string);
    if let Some(name) = field("unknown field `") {
        // The offending key is a leaf whose last segment is the field, preferably near the line.
        let candidates: Vec<String> = lines
            .iter()
            .filter(|(path, _)| path.contains(&name))
            .map(|(path, _)| {
                let end = path.iter().position(|k| *k == name).unwrap_or(path.len() - 1);
                dotted(&path[..=end])
            })
            .collect();
        let near = located.and_then(|at| {
            let table = at.rsplit_once('.').map_or("", |(t, _)| t);
            candidates.iter().find(|c| c.starts_with(table)).cloned()
        });
        if let Some(key) = near.or_else(|| candidates.first().cloned()) {
            return key;
        }
    }
    if let Some(name) = field("missing field `") {
        let table = located.and_then(|at| at.rsplit_once('.')).map_or(String::new(), |(t, _)| format!("{t}."));
        return format!("{table}{name}");
    }
    if let Some(key) = located.and_then(|at| holder_of_value(message, at, lines)) {
        return key;
    }
    located.unwrap_or_default().to_string()
}

/// For an `invalid type` / `invalid value` message about a value inside a table that serde read
/// as a whole (an internally tagged or flattened table, whose errors point at the table's first
/// line), the one leaf of that table holding the value the message quotes.
fn holder_of_value(message: &str, located: &str, lines: &[(Vec<String>, Value)]) -> Option<String> {
    let rest = message.strip_prefix("invalid type: ").or_else(|| message.strip_prefix("invalid value: "))?;
    let (unexpected, _) = rest.split_once(", expected")?;
    let table = located.rsplit_once('.').map_or("", |(t, _)| t);
    let mut holders = lines.iter().filter(|(path, value)| {
        let in_table = table.is_empty() || dotted(path).starts_with(&format!("{table}."));
        in_table && unexpected_of(value).is_some_and(|u| u == unexpected)
    });
    match (holders.next(), holders.next()) {
        (Some((path, _)), None) => Some(dotted(path)),
        _ => None,
    }
}

/// How serde's `invalid type` messages describe a TOML value (`string "0.8"`, `integer `3``).
fn unexpected_of(value: &Value) -> Option<String> {
    match value {
        Value::String(s) => Some(format!("string {s:?}")),
        Value::Integer(i) => Some(format!("integer `{i}`")),
        Value::Boolean(b) => Some(format!("boolean `{b}`")),
        Value::Array(_) => Some("sequence".into()),
        _ => None,
    }
}

/// The first key of `input` that `written` (the configuration serialised back) lacks.
fn unused_key(input: &Table, written: &Table, path: &mut Vec<String>) -> Option<String> {
    for (key, value) in input {
        path.push(key.clone());
        let found = match (value, written.get(key)) {
            (_, None) => Some(dotted(path)),
            (Value::Table(a), Some(Value::Table(b))) => unused_key(a, b, path),
            (Value::Array(a), Some(Value::Array(b))) if a.len() == b.len() => {
                a.iter().zip(b).enumerate().find_map(|(i, pair)| match pair {
                    (Value::Table(x), Value::Table(y)) => {
                        let last = path.pop().unwrap_or_default();
                        path.push(format!("{last}[{i}]"));
                        let found = unused_key(x, y, path);
                        path.pop();
                        path.push(last);
                        found
                    }
                    _ => None,
                })
            }
            _ => None,
        };
        path.pop();
        if found.is_some() {
            return found;
        }
    }
    None
}
