//! Reading a configuration from a state dict's keys and shapes: what the RAFT-Stereo and DEFOM
//! reader (`checkpoint_config`) and the IGEV-Stereo reader (`igev_config`) both ask of the keys.

use std::collections::BTreeMap;

/// Axis `axis` of `key`'s shape; a missing key or axis is a problem (and 0).
pub(crate) fn dim(keys: &BTreeMap<&str, &[usize]>, key: &str, axis: usize, problems: &mut Vec<String>) -> usize {
    match keys.get(key) {
        Some(s) if s.len() > axis => s[axis],
        Some(s) => {
            problems.push(format!("'{key}' has shape {s:?}"));
            0
        }
        None => {
            problems.push(format!("missing key '{key}'"));
            0
        }
    }
}

/// The GRU levels: one `context_zqr_convs.{i}` per level; other than 1 to 3 is a problem.
pub(crate) fn gru_levels(keys: &BTreeMap<&str, &[usize]>, problems: &mut Vec<String>) -> usize {
    let levels = (0..).take_while(|i| keys.contains_key(format!("context_zqr_convs.{i}.weight").as_str())).count();
    if !(1..=3).contains(&levels) {
        problems.push(format!("{levels} 'context_zqr_convs.{{i}}.weight' keys (a model has 1, 2 or 3 GRU levels)"));
    }
    levels
}
