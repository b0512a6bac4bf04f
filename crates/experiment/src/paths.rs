//! Paths in experiment files are relative to the file that writes them.
//!
//! Design decision: `base` has always been relative to the inheriting file, and a file inheriting
//! from another folder (an experiment of one's own on `experiments/smoke/baseline.toml`) must find
//! that base's data where its author put it, whatever the working directory. So every path a file
//! writes (the keys of [`PATH_KEYS`]) is made absolute against the file's folder as the file is
//! read, before files merge; an absolute path stays as it is. `check --show` and every error
//! about a path show the absolute path.

use std::path::{Component, Path, PathBuf};

use toml::{Table, Value};

/// The keys that hold paths, as dotted keys where `[]` stands for every element of an array of
/// tables; the prior's keys hold at every depth of a cache's `inner` provider too.
pub const PATH_KEYS: [&str; 8] = [
    "train.init",
    "train.feature_init",
    "prior.weights",
    "prior.dir",
    "data.sources[].root",
    "data.sources[].photos.dir",
    "data.validation.photos.dir",
    "benchmarks[].root",
];

/// `path` joined to `folder` when relative, made absolute against the working directory, with
/// `.` and `..` resolved lexically (a path through a missing folder still resolves).
pub fn resolve(folder: &Path, path: &str) -> PathBuf {
    let joined = folder.join(path);
    let absolute = std::path::absolute(&joined).unwrap_or(joined);
    let mut out = PathBuf::new();
    for part in absolute.components() {
        match part {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other.as_os_str()),
        }
    }
    out
}

fn resolve_value(value: &mut Value, folder: &Path) {
    // The name of an official checkpoint (`depth-anything-v2-base`) stays a name.
    if let Value::String(text) = value
        && !text.is_empty()
        && !dgstereo_weights::is_name(text)
    {
        *text = resolve(folder, text).display().to_string();
    }
}

fn resolve_in(table: &mut Table, keys: &[&str], folder: &Path) {
    let Some((first, rest)) = keys.split_first() else { return };
    let (name, each) = match first.strip_suffix("[]") {
        Some(name) => (name, true),
        None => (*first, false),
    };
    let Some(value) = table.get_mut(name) else { return };
    match (value, rest.is_empty(), each) {
        (value, true, false) => resolve_value(value, folder),
        (Value::Table(inner), false, false) => resolve_in(inner, rest, folder),
        (Value::Array(items), false, true) => {
            for item in items {
                if let Value::Table(inner) = item {
                    resolve_in(inner, rest, folder);
                }
            }
        }
        _ => {}
    }
}

/// The prior table and its nested `inner` providers (a cache of a cache of ...).
fn resolve_prior(prior: &mut Table, folder: &Path) {
    for key in ["weights", "dir"] {
        if let Some(value) = prior.get_mut(key) {
            resolve_value(value, folder);
        }
    }
    if let Some(Value::Table(inner)) = prior.get_mut("inner") {
        resolve_prior(inner, folder);
    }
}

/// Makes every path `table` (one file's own keys, before merging) writes absolute against
/// `folder`, the file's folder.
pub fn resolve_paths(table: &mut Table, folder: &Path) {
    for key in PATH_KEYS.iter().filter(|k| !k.starts_with("prior.")) {
        let parts: Vec<&str> = key.split('.').collect();
        resolve_in(table, &parts, folder);
    }
    if let Some(Value::Table(prior)) = table.get_mut("prior") {
        resolve_prior(prior, folder);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_join_the_file_folder_and_absolute_ones_stay() {
        let mut table: Table = toml::from_str(
            r#"
[train]
init = "../weights/a.safetensors"
[prior]
kind = "cache"
dir = "cache"
[prior.inner]
kind = "depth-anything-v2"
weights = "/models/vitb.pth"
[[data.sources]]
kind = "folder"
root = "./pairs"
photos = { dir = "photos", share = 0.5 }
[[benchmarks]]
root = "../../assets/cones"
"#,
        )
        .unwrap();
        resolve_paths(&mut table, Path::new("/work/exp/smoke"));
        let get = |t: &Table, keys: &[&str]| {
            let mut v = &t[keys[0]];
            for k in &keys[1..] {
                v = match k.parse::<usize>() {
                    Ok(i) => &v.as_array().unwrap()[i],
                    Err(_) => &v[*k],
                };
            }
            v.as_str().unwrap().to_string()
        };
        assert_eq!(get(&table, &["train", "init"]), "/work/exp/weights/a.safetensors");
        assert_eq!(get(&table, &["prior", "dir"]), "/work/exp/smoke/cache");
        assert_eq!(get(&table, &["prior", "inner", "weights"]), "/models/vitb.pth");
        assert_eq!(get(&table, &["data", "sources", "0", "root"]), "/work/exp/smoke/pairs");
        assert_eq!(get(&table, &["data", "sources", "0", "photos", "dir"]), "/work/exp/smoke/photos");
        assert_eq!(get(&table, &["benchmarks", "0", "root"]), "/work/assets/cones");
    }

    #[test]
    fn names_of_official_checkpoints_stay_names() {
        let mut table: Table = toml::from_str(
            "[train]\ninit = \"raftstereo-sceneflow\"\n[prior]\nkind = \"depth-anything-v2\"\nweights = \"depth-anything-v2-base\"\n",
        )
        .unwrap();
        resolve_paths(&mut table, Path::new("/work/exp"));
        assert_eq!(table["train"]["init"].as_str(), Some("raftstereo-sceneflow"));
        assert_eq!(table["prior"]["weights"].as_str(), Some("depth-anything-v2-base"));
        // A file of that name in a folder is a path.
        let mut table: Table = toml::from_str("[train]\ninit = \"w/raftstereo-sceneflow\"\n").unwrap();
        resolve_paths(&mut table, Path::new("/work/exp"));
        assert_eq!(table["train"]["init"].as_str(), Some("/work/exp/w/raftstereo-sceneflow"));
    }
}
