//! Sweeps: a `[sweep]` table of dotted keys and value lists, expanded into one run per
//! combination.
//!
//! ```toml
//! [sweep]
//! "loss.tau" = [0.8, 0.9, 1.0]
//! "model.fusion.target" = ["both", "context-only"]
//! ```
//! gives six runs; keys are taken in alphabetical order and the last varies fastest, and each run
//! is named `name/loss.tau=0.8,model.fusion.target=both`. A key must exist in the configuration
//! resolved without the sweep, counting defaults: a key that a file does not write but the
//! configuration has (`loss.gamma` under the default loss) may be swept, a misspelt one may not.

use dgstereo_core::{Error, Result};
use toml::{Table, Value};

use crate::inherit::Document;
use crate::keys::{self, Provenance, split};

/// The table of one run before deserialisation.
#[derive(Debug, Clone)]
pub struct RunTable {
    /// The merged table with `name` (and `description`) set and the sweep applied.
    pub table: Table,
    /// The file that set each key.
    pub provenance: Provenance,
}

/// The runs of a document: one per combination of its sweep, or the document itself.
///
/// # Errors
/// `[sweep]` is not a table of non-empty lists, names a reserved or unknown key, or the document
/// without its sweep does not deserialise (its own error).
pub fn expand(document: &Document) -> Result<Vec<RunTable>> {
    let mut table = document.table.clone();
    let mut provenance = document.provenance.clone();
    let sweep = match table.remove("sweep") {
        None => Table::new(),
        Some(Value::Table(sweep)) => sweep,
        Some(other) => {
            let file = keys::file_of(&provenance, "sweep", &document.source);
            return Err(Error::format(
                file,
                format!("sweep: expected a table of key = [values], found {}", other.type_str()),
            ));
        }
    };
    let sweep_provenance = provenance.clone();
    let file_of_sweep = |key: &str| {
        let sweep_key = format!("sweep.{key}");
        sweep_provenance
            .get(&sweep_key)
            .cloned()
            .unwrap_or_else(|| keys::file_of(&sweep_provenance, "sweep", &document.source))
    };
    provenance.retain(|k, _| k != "sweep" && !k.starts_with("sweep."));
    table.insert("name".into(), Value::String(document.name.clone()));
    provenance.insert("name".into(), document.source.clone());
    if let Some(description) = &document.description {
        table.insert("description".into(), Value::String(description.clone()));
        provenance.insert("description".into(), document.source.clone());
    }
    if sweep.is_empty() {
        return Ok(vec![RunTable { table, provenance }]);
    }

    // The configuration without the sweep, every default filled in: the keys a sweep may name.
    let unswept = keys::deserialize(&table, &provenance, &document.source)?;
    let complete = match Value::try_from(&unswept) {
        Ok(Value::Table(t)) => t,
        _ => Table::new(),
    };
    let mut axes: Vec<(String, Vec<Value>)> = Vec::with_capacity(sweep.len());
    for (key, values) in sweep {
        let file = file_of_sweep(&key);
        let values = match values {
            Value::Array(values) if !values.is_empty() => values,
            other => {
                return Err(Error::format(
                    file,
                    format!("sweep.\"{key}\": expected a non-empty list of values, found {}", describe(&other)),
                ));
            }
        };
        let path = split(&key);
        if matches!(path[0].as_str(), "name" | "description" | "base" | "sweep") {
            return Err(Error::format(file, format!("sweep.\"{key}\": '{}' cannot be swept", path[0])));
        }
        if keys::get(&table, &path).is_none() && keys::get(&complete, &path).is_none() {
            return Err(Error::format(file, format!("sweep.\"{key}\": no such key{}", known_keys(&complete, &path))));
        }
        axes.push((key, values));
    }

    let combinations = axes.iter().map(|(_, values)| values.len()).product::<usize>();
    let mut runs = Vec::with_capacity(combinations);
    for index in 0..combinations {
        let mut run = table.clone();
        let mut run_provenance = provenance.clone();
        let mut parts = Vec::with_capacity(axes.len());
        let mut rest = index;
        let mut chosen = vec![0; axes.len()];
        for (slot, (_, values)) in chosen.iter_mut().zip(&axes).rev() {
            *slot = rest % values.len();
            rest /= values.len();
        }
        for ((key, values), &choice) in axes.iter().zip(&chosen) {
            let value = values[choice].clone();
            let path = split(key);
            // A swept table (or a kind) replaces what was there, like an inheriting file.
            keys::set(&mut run, &path, value.clone())
                .map_err(|problem| Error::format(file_of_sweep(key), format!("sweep.\"{key}\": {problem}")))?;
            let dotted = keys::dotted(&path);
            run_provenance.retain(|k, _| *k != dotted && !k.starts_with(&format!("{dotted}.")));
            run_provenance.insert(dotted, file_of_sweep(key));
            parts.push(format!("{key}={}", render(&value)));
        }
        let name = format!("{}/{}", document.name, parts.join(","));
        run.insert("name".into(), Value::String(name));
        runs.push(RunTable { table: run, provenance: run_provenance });
    }
    Ok(runs)
}

/// A sweep value in a run name: strings bare, everything else as compact TOML.
pub fn render(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        Value::Array(items) => format!("[{}]", items.iter().map(render).collect::<Vec<_>>().join(",")),
        other => other.to_string().replace(' ', ""),
    }
}

fn describe(value: &Value) -> String {
    match value {
        Value::Array(_) => "an empty list".into(),
        other => format!("{} {other}", other.type_str()),
    }
}

/// `" (keys of 'loss': gamma, kind, ...)"` for the deepest existing table on `path`.
fn known_keys(complete: &Table, path: &[String]) -> String {
    for depth in (0..path.len()).rev() {
        let table =
            if depth == 0 { Some(complete) } else { keys::get(complete, &path[..depth]).and_then(Value::as_table) };
        if let Some(table) = table {
            let names: Vec<&str> =
                table.keys().map(String::as_str).filter(|k| *k != "name" && *k != "description").collect();
            let owner =
                if depth == 0 { "the top level".to_string() } else { format!("'{}'", keys::dotted(&path[..depth])) };
            return format!(" (keys of {owner}: {})", names.join(", "));
        }
    }
    String::new()
}
