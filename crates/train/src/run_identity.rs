//! A run's identity: the keys of its resolved configuration that change what it trains.
//!
//! Design decision: a run folder belongs to one training. Its name, its description, the
//! benchmarks it is scored on (their folders, iterations and sizes) and where a scheduler runs it
//! do not change a single weight, so they may change between the run and a later `--resume` or `ablate`; every other
//! key does, and a difference there means the folder holds another run. A key added to the
//! schema after a run was trained is absent from its folder's configuration; both sides are read
//! through the schema ([`ExperimentConfig`]) first, so such a key counts as its default, and
//! differs only where the configuration given now sets it otherwise.

use dgstereo_core::{Error, Result};
use dgstereo_experiment::ExperimentConfig;
use serde::Deserialize;
use toml::Value;

/// Top-level keys that describe, score or place a run and do not change its training.
pub const SCORING_KEYS: [&str; 4] = ["name", "description", "benchmarks", "launcher"];

/// Every leaf of `value` under `prefix`, as `(dotted key, value)`; arrays of tables are entered
/// by index (`data.sources[0].root`), other arrays are values.
fn leaves(prefix: &str, value: &Value, out: &mut Vec<(String, Value)>) {
    match value {
        Value::Table(table) => {
            for (key, v) in table {
                let key = if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") };
                leaves(&key, v, out);
            }
        }
        Value::Array(items) if !items.is_empty() && items.iter().all(Value::is_table) => {
            for (i, v) in items.iter().enumerate() {
                leaves(&format!("{prefix}[{i}]"), v, out);
            }
        }
        other => out.push((prefix.to_string(), other.clone())),
    }
}

fn training_leaves(text: &str, what: &str) -> Result<Vec<(String, Value)>> {
    let table: toml::Table =
        toml::from_str(text).map_err(|e| Error::format(what, format!("not a resolved configuration: {e}")))?;
    let table = with_defaults(table);
    let mut out = Vec::new();
    for (key, value) in table.iter().filter(|(k, _)| !SCORING_KEYS.contains(&k.as_str())) {
        leaves(key, value, &mut out);
    }
    Ok(out)
}

/// `table` with every key the schema defaults filled in (an old run's configuration lacks the
/// keys added since), or `table` as it is where it is not a configuration the schema reads today
/// (a key renamed or removed since): its keys are then compared as written.
fn with_defaults(table: toml::Table) -> toml::Table {
    let table = with_layout_named(table);
    let Ok(config) = ExperimentConfig::deserialize(Value::Table(table.clone())) else {
        return table;
    };
    toml::from_str(&config.to_toml()).unwrap_or(table)
}

/// `table` with its encoder layout named by `model.encoder.layout` where it was written before
/// that key replaced `shared_backbone` and `feature_network` (a run trained then), as a
/// checkpoint's stored configuration is read ([`dgstereo_model::name_the_encoder_layout`]); a
/// table whose keys name no layout stays as it is, and so differs.
fn with_layout_named(mut table: toml::Table) -> toml::Table {
    let Some(model) = table.get_mut("model") else { return table };
    let Ok(mut json) = serde_json::to_value(&*model) else { return table };
    if dgstereo_model::name_the_encoder_layout(&mut json).is_ok()
        && let Ok(named) = Value::try_from(json)
    {
        *model = named;
    }
    table
}

/// The training keys that differ between the configuration a run was trained with (`run`) and
/// the one given now (`here`), each as `key: <value here> here, <value in the run> in the run`
/// (`absent` where a side lacks the key), in key order.
///
/// # Errors
/// Either text is not TOML.
pub fn training_differences(run: &str, here: &str) -> Result<Vec<String>> {
    let run = training_leaves(run, "the run's configuration")?;
    let here = training_leaves(here, "this configuration")?;
    let mut keys: Vec<&String> = run.iter().chain(&here).map(|(k, _)| k).collect();
    keys.sort();
    keys.dedup();
    let find = |side: &[(String, Value)], key: &str| side.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone());
    let show = |v: Option<Value>| v.map_or("absent".to_string(), |v| v.to_string());
    Ok(keys
        .into_iter()
        .filter_map(|key| {
            let (a, b) = (find(&here, key), find(&run, key));
            (a != b).then(|| format!("{key}: {} here, {} in the run", show(a), show(b)))
        })
        .collect())
}

/// The training keys that differ between the run in folder `out` (its `config.toml`) and the
/// configuration `here` ([`training_differences`]); none when the folder holds no run yet.
///
/// # Errors
/// The folder's `config.toml` cannot be read or is not TOML.
pub fn folder_differences(out: &std::path::Path, here: &str) -> Result<Vec<String>> {
    let path = out.join("config.toml");
    if !path.is_file() {
        return Ok(Vec::new());
    }
    let stored = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
    training_differences(&stored, here).map_err(|e| e.context(path.display().to_string()))
}

/// Checks that folder `out` holds no run or the run `here` configures: else the error of
/// [`another_run`], which changes nothing.
///
/// # Errors
/// The folder holds another run, or its `config.toml` cannot be read.
pub fn check_folder(out: &std::path::Path, here: &str) -> Result<()> {
    let differences = folder_differences(out, here)?;
    if differences.is_empty() { Ok(()) } else { Err(another_run(out, &differences)) }
}

/// The error for a folder whose run was trained with another configuration: the first
/// differing key is the error's key, every difference is listed.
pub fn another_run(folder: &std::path::Path, differences: &[String]) -> Error {
    let key = differences.first().and_then(|d| d.split(':').next()).unwrap_or("config").to_string();
    Error::config(
        key,
        format!(
            "{} holds a run trained with another configuration ({}); nothing was changed: \
             train into another folder, or restore the run's configuration",
            folder.display(),
            differences.join("; ")
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const RUN: &str = r#"
name = "a"
[train]
lr = 0.0002
steps = 10
[[data.sources]]
kind = "synthetic"
width = 96
[[benchmarks]]
name = "cones"
root = "/x"
"#;

    #[test]
    fn scoring_keys_may_change_and_training_keys_are_named() {
        let renamed = RUN.replace("name = \"a\"", "name = \"b\"").replace("root = \"/x\"", "root = \"/y\"");
        assert!(training_differences(RUN, &renamed).unwrap().is_empty());
        let faster = RUN.replace("lr = 0.0002", "lr = 0.0004").replace("width = 96", "width = 128");
        let d = training_differences(RUN, &faster).unwrap();
        assert_eq!(
            d,
            vec!["data.sources[0].width: 128 here, 96 in the run", "train.lr: 0.0004 here, 0.0002 in the run"]
        );
        let more = format!("{RUN}\n[loss]\nkind = \"edge-aware\"\n");
        assert_eq!(
            training_differences(RUN, &more).unwrap(),
            vec!["loss.kind: \"edge-aware\" here, absent in the run"]
        );
        let e = another_run(std::path::Path::new("runs/x"), &d).to_string();
        assert!(e.contains("data.sources[0].width") && e.contains("runs/x") && e.contains("train.lr"), "{e}");
    }

    /// A complete configuration as a run folder keeps it, without the `[model]` keys that
    /// `drop` names (keys added to the schema after the run was trained).
    fn stored_without(config: &ExperimentConfig, drop: &[&str]) -> String {
        let mut table: toml::Table = toml::from_str(&config.to_toml()).unwrap();
        let model = table.get_mut("model").and_then(Value::as_table_mut).unwrap();
        for key in drop {
            assert!(model.remove(*key).is_some(), "the resolved configuration writes model.{key}");
        }
        toml::to_string(&table).unwrap()
    }

    #[test]
    fn a_key_absent_in_an_old_run_is_its_default() {
        let here: ExperimentConfig = toml::from_str("name = \"a\"").unwrap();
        let old = stored_without(&here, &["initial_disparity", "monocular"]);
        assert!(training_differences(&old, &here.to_toml()).unwrap().is_empty());
        // Set otherwise now, it is a difference, shown against the default the run trained with.
        let mut other = here.clone();
        other.model.initial_disparity = dgstereo_model::InitialDisparity::scaled_inverse_depth();
        let d = training_differences(&old, &other.to_toml()).unwrap();
        assert!(d.iter().all(|k| k.starts_with("model.initial_disparity.")), "{d:?}");
        let kind = "model.initial_disparity.kind: \"scaled-inverse-depth\" here, \"zero\" in the run";
        assert!(d.iter().any(|k| k == kind), "{d:?}");
    }

    /// A run trained before `encoder.layout` named the layout by `shared_backbone` and
    /// `feature_network`; it is the same run as a configuration whose layout they name.
    #[test]
    fn a_run_stored_under_the_two_layout_keys_is_the_run_its_layout_names() {
        let here: ExperimentConfig =
            toml::from_str("name = \"a\"\n[model.encoder]\nlayout = \"shared-backbone\"").unwrap();
        let mut table: toml::Table = toml::from_str(&here.to_toml()).unwrap();
        let encoder = table["model"].get_mut("encoder").and_then(Value::as_table_mut).unwrap();
        assert!(encoder.remove("layout").is_some());
        encoder.insert("shared_backbone".into(), Value::Boolean(true));
        encoder.insert("feature_network".into(), Value::String("residual".into()));
        let old = toml::to_string(&table).unwrap();
        assert!(training_differences(&old, &here.to_toml()).unwrap().is_empty());
        let separate = here.to_toml().replace("layout = \"shared-backbone\"", "layout = \"separate\"");
        let d = training_differences(&old, &separate).unwrap();
        assert_eq!(d, vec!["model.encoder.layout: \"separate\" here, \"shared-backbone\" in the run"]);
        // A pair that names no layout is compared as written.
        let none = old.replace("feature_network = \"residual\"", "feature_network = \"mobilenet-pyramid\"");
        let d = training_differences(&none, &here.to_toml()).unwrap();
        assert!(d.iter().any(|k| k.starts_with("model.encoder.shared_backbone")), "{d:?}");
    }
}
