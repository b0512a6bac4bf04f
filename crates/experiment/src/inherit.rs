//! Reading an experiment file with its chain of `base` files into one merged table.
//!
//! Merge rule: tables merge recursively and the inheriting file wins key by key; a table whose
//! `kind` differs between the two files is replaced whole (the fields of one variant mean
//! nothing to another); every other value, arrays included, is replaced. `name`, `description`
//! and `base` are per file and never inherited.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use toml::{Table, Value};

use crate::keys::{Provenance, dotted, leaves};

/// Keys that belong to one file and are not inherited.
const PER_FILE: [&str; 3] = ["name", "description", "base"];

/// An experiment file merged with its bases.
#[derive(Debug, Clone)]
pub struct Document {
    /// The file that was read (as given).
    pub source: PathBuf,
    /// The run name: the file's `name`, or its stem.
    pub name: String,
    /// The file's `description`.
    pub description: Option<String>,
    /// The merged sections (`model`, `prior`, `loss`, `train`, `data`, `sweep`, and whatever
    /// unknown keys the files hold, which deserialisation reports).
    pub table: Table,
    /// The file that set each key of `table`.
    pub provenance: Provenance,
}

/// Reads `path` and its bases.
///
/// # Errors
/// The file (or a base) cannot be read or parsed, `base` is not a string, a base is missing,
/// or the chain of bases returns to a file already in it.
pub fn read(path: &Path) -> Result<Document> {
    read_chain(path, &mut Vec::new())
}

fn read_chain(path: &Path, chain: &mut Vec<PathBuf>) -> Result<Document> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut table: Table = toml::from_str(&text).map_err(|e| Error::format(path, format!("not valid TOML: {e}")))?;
    let name = match table.remove("name") {
        None => path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        Some(Value::String(name)) => name,
        Some(other) => return Err(Error::format(path, format!("name: expected a string, found {}", other.type_str()))),
    };
    let description = match table.remove("description") {
        None => None,
        Some(Value::String(text)) => Some(text),
        Some(other) => {
            return Err(Error::format(path, format!("description: expected a string, found {}", other.type_str())));
        }
    };
    let base = match table.remove("base") {
        None => None,
        Some(Value::String(base)) => Some(base),
        Some(other) => {
            return Err(Error::format(
                path,
                format!("base: expected a file name (string), found {}", other.type_str()),
            ));
        }
    };

    let mut provenance = Provenance::new();
    let mut merged = Table::new();
    if let Some(base) = base {
        let base_path = path.parent().unwrap_or(Path::new("")).join(&base);
        if !base_path.is_file() {
            return Err(Error::format(path, format!("base = \"{base}\": {} is not a file", base_path.display())));
        }
        let identity = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        chain.push(identity);
        let base_identity = std::fs::canonicalize(&base_path).unwrap_or_else(|_| base_path.clone());
        if let Some(start) = chain.iter().position(|p| *p == base_identity) {
            let cycle: Vec<String> =
                chain[start..].iter().chain([&base_identity]).map(|p| p.display().to_string()).collect();
            return Err(Error::format(path, format!("base = \"{base}\": inheritance cycle {}", cycle.join(" -> "))));
        }
        let parent = read_chain(&base_path, chain)?;
        chain.pop();
        merged = parent.table;
        provenance = parent.provenance;
    }
    debug_assert!(PER_FILE.iter().all(|k| !table.contains_key(*k)));
    crate::paths::resolve_paths(&mut table, path.parent().unwrap_or(Path::new("")));
    merge(&mut merged, table, &mut Vec::new(), &mut provenance, path);
    Ok(Document { source: path.to_path_buf(), name, description, table: merged, provenance })
}

/// Merges `over` into `base` (the rule of this module), recording `file` for every key it sets.
pub fn merge(base: &mut Table, over: Table, prefix: &mut Vec<String>, provenance: &mut Provenance, file: &Path) {
    for (key, value) in over {
        prefix.push(key.clone());
        match (base.get_mut(&key), value) {
            (Some(Value::Table(old)), Value::Table(new)) if !kind_changes(old, &new) => {
                if new.is_empty() && old.is_empty() {
                    provenance.insert(dotted(prefix), file.to_path_buf());
                }
                merge(old, new, prefix, provenance, file);
            }
            (_, value) => {
                forget(provenance, &dotted(prefix));
                record(provenance, prefix, &value, file);
                base.insert(key.clone(), value);
            }
        }
        prefix.pop();
    }
}

/// Whether both tables name a `kind` and the kinds differ.
fn kind_changes(old: &Table, new: &Table) -> bool {
    matches!((old.get("kind"), new.get("kind")), (Some(a), Some(b)) if a != b)
}

/// Removes `key` and every key below it.
fn forget(provenance: &mut Provenance, key: &str) {
    let below = format!("{key}.");
    provenance.retain(|k, _| k != key && !k.starts_with(&below));
}

/// Records `file` for `value` at `prefix` and for every leaf below it.
fn record(provenance: &mut Provenance, prefix: &[String], value: &Value, file: &Path) {
    provenance.insert(dotted(prefix), file.to_path_buf());
    if let Value::Table(table) = value {
        for (path, _) in leaves(table) {
            let full: Vec<String> = prefix.iter().cloned().chain(path).collect();
            provenance.insert(dotted(&full), file.to_path_buf());
        }
    }
}
