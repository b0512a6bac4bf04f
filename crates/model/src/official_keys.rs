//! The state-dict keys of official RAFT-Stereo (and DEFOM-Stereo) checkpoints, read from a file
//! or derived from a model.
//!
//! [`pth_keys`] lists a `.pth` file's tensors as the file names them, without the `DataParallel`
//! prefix `module.`. [`model_official_keys`] lists the keys an official checkpoint of a model's
//! architecture holds: our module paths mapped back through the loader's renames
//! ([`official_key_of_module_path`], the inverse of
//! [`crate::checkpoint::module_path_of_official_key`]). Keys the reference stores redundantly
//! (`downsample.1.*`, a copy of the block's `norm3`, and BatchNorm's `num_batches_tracked`) are
//! [`redundant`] and left out of both lists' comparisons.

use std::path::Path;

use burn::store::{BurnToPyTorchAdapter, KeyRemapper, ModuleSnapshot, ModuleStore, PytorchStore};
use dgstereo_core::{Error, Result};

use crate::RaftStereo;

/// A state-dict key and its tensor's shape.
pub type KeyShape = (String, Vec<usize>);

/// Renames from our module paths to the reference's state-dict keys, applied in order.
const INVERSE_RENAMES: &[(&str, &str)] = &[
    // Enum modules (`Norm::Batch`, ...) add their variant to our paths; the reference has none.
    (r"\.[A-Z][A-Za-z0-9]*\.", "."),
    // The encoder layout's module (`encoder.Separate.`, `encoder.Shared.`) holds `fnet`, `cnet`
    // and `conv2`, which the reference has at the top level.
    (r"^encoder\.", ""),
    (r"(outputs08|outputs16)\.(\d+)\.block\.", "$1.$2.0."),
    (r"(outputs08|outputs16)\.(\d+)\.conv\.", "$1.$2.1."),
    (r"downsample\.(weight|bias)$", "downsample.0.$1"),
    (r"^conv2\.block\.", "conv2.0."),
    (r"^conv2\.conv\.", "conv2.1."),
    (r"update_block\.mask\.conv1\.", "update_block.mask.0."),
    (r"update_block\.mask\.conv2\.", "update_block.mask.2."),
    // DEFOM-Stereo's Depth Anything V2 and the PyTorch names of its DPT heads.
    (r"^monocular\.", "defomencoder.depth_anything."),
    (r"\.(depth_head|depth_feat)\.upsample_4x\.", ".$1.resize_layers.0."),
    (r"\.(depth_head|depth_feat)\.upsample_2x\.", ".$1.resize_layers.1."),
    (r"\.(depth_head|depth_feat)\.downsample_2x\.", ".$1.resize_layers.3."),
    (r"\.output_conv2_hidden\.", ".output_conv2.0."),
    (r"\.output_conv2_out\.", ".output_conv2.2."),
    (r"\.res_conf_unit([12])\.", ".resConfUnit$1."),
];

/// The official state-dict key (without `module.`) of one of our module paths (enum variants,
/// such as a norm's `Batch`, dropped).
pub fn official_key_of_module_path(path: &str) -> String {
    let renames = KeyRemapper::from_patterns(INVERSE_RENAMES.to_vec()).expect("the renames are valid patterns");
    let mut key = path.to_string();
    for (pattern, replacement) in renames.patterns.iter() {
        key = pattern.replace_all(&key, replacement.as_str()).into_owned();
    }
    key
}

/// Whether a key is one the reference stores redundantly (`num_batches_tracked`,
/// `downsample.1.*`, the same BatchNorm as the block's `norm3`, and DEFOM-Stereo's constant
/// ImageNet `mean` and `std`).
pub fn redundant(key: &str) -> bool {
    key.ends_with("num_batches_tracked") || key.contains("downsample.1.") || key == "mean" || key == "std"
}

/// The keys (official names, no `module.` prefix) and shapes an official checkpoint of
/// `model`'s architecture holds, redundant ones left out, sorted by key.
pub fn model_official_keys(model: &RaftStereo) -> Vec<KeyShape> {
    let tensors = model.collect(None, Some(Box::new(BurnToPyTorchAdapter)), false);
    // IGEV-Stereo's renames follow RAFT-Stereo's inverse ones (`crate::igev_keys::to_official`).
    let igev = match model.geometry {
        Some(_) => crate::igev_keys::to_official(),
        None => Vec::new(),
    };
    let igev = KeyRemapper::from_patterns(igev).expect("the renames are valid patterns");
    let mut keys: Vec<KeyShape> = tensors
        .iter()
        .map(|t| {
            let key = official_key_of_module_path(&t.name);
            let key = igev.patterns.iter().fold(key, |k, (p, r)| p.replace_all(&k, r.as_str()).into_owned());
            (key, t.shape.to_vec())
        })
        .collect();
    keys.sort();
    keys
}

/// Every tensor of an official `.pth` checkpoint: its key (the `module.` prefix removed) and
/// shape, sorted by key.
pub fn pth_keys(path: &Path) -> Result<Vec<KeyShape>> {
    if !path.is_file() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file")));
    }
    let mut store = PytorchStore::from_file(path).map_indices_contiguous(false);
    let tensors = store
        .get_all_tensors()
        .map_err(|e| Error::Checkpoint { path: path.into(), message: format!("cannot read checkpoint: {e}") })?;
    let mut keys: Vec<KeyShape> =
        tensors.iter().map(|(k, t)| (k.strip_prefix("module.").unwrap_or(k).to_string(), t.shape.to_vec())).collect();
    keys.sort();
    Ok(keys)
}
