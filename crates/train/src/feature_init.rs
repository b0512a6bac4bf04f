//! `train.feature_init`: ImageNet weights in IGEV-Stereo's MobileNetV2 feature trunk before
//! training, as the official `Feature` builds `timm.create_model('mobilenetv2_100',
//! pretrained=True)`.
//!
//! The file is a state dict of timm's `mobilenetv2_100` in timm 0.5.4's layout (`.pth`, as the
//! ImageNet checkpoint `mobilenetv2_100_ra-b33bc2c4.pth`, or `.safetensors`): `conv_stem`, `bn1`
//! and `blocks.{stage}.{block}`. IGEV-Stereo regroups timm's stages (`layers = [1, 2, 3, 5, 6]`):
//! `block0` is stage 0, `block1` stage 1, `block2` stage 2, `block3` stages 3 and 4 and `block4`
//! stage 5 (the official-key table [`TIMM_MOBILENET_TRUNK`]). Stage 6, `conv_head`, `bn2`, the
//! classifier and the batch norms' `num_batches_tracked` are not in the network and are ignored. Every tensor of the trunk must
//! come from the file with its shape, so a file that does not fit is an error naming
//! `train.feature_init`, the file and the timm key; the decoder (`deconv*`, `conv4`) keeps its
//! initialisation, as in the official code.

use std::path::Path;

use burn::store::{
    ApplyError, ApplyResult, KeyRemapper, ModuleSnapshot, ModuleStore, PyTorchToBurnAdapter, PytorchStore,
    SafetensorsStore,
};
use dgstereo_core::key_notation::{self, load_patterns, save_patterns};
use dgstereo_core::{Error, Result};
use dgstereo_encoder::{Encoders, MobileNetPyramid};
use dgstereo_model::RaftStereo;
use dgstereo_model::official_keys::TIMM_MOBILENET_TRUNK;

/// The key the errors name.
const KEY: &str = "train.feature_init";

/// The module paths of the trunk (below the feature network), which must come from the file.
const TRUNK: [&str; 7] = ["conv_stem.", "bn1.", "block0.", "block1.", "block2.", "block3.", "block4."];

/// The timm key of a path of the feature network's trunk (`block3.1.0.conv_pw.weight` is
/// `blocks.4.0.conv_pw.weight`); other paths are their own.
pub fn timm_key(path: &str) -> String {
    let remapper = KeyRemapper::from_patterns(save_patterns(TIMM_MOBILENET_TRUNK)).expect("the table compiles");
    key_notation::apply(&remapper, path)
}

/// `model` with the timm ImageNet weights of `weights` in its MobileNetV2 trunk, and a notice of
/// what was loaded and ignored.
///
/// # Errors
/// [`Error::Config`] keyed `train.feature_init` when the model has no MobileNetV2 feature
/// network, or the file is missing, unreadable, lacks a tensor of the trunk or holds one of
/// another shape (the message names the file and the timm key).
pub fn load_feature_init(mut model: RaftStereo, weights: &Path) -> Result<(RaftStereo, String)> {
    let Encoders::Pyramid(encoders) = &mut model.encoder else {
        return Err(Error::config(
            KEY,
            "the model has no MobileNetV2 feature network to load into: set model.encoder.layout = \
             \"mobilenet-pyramid\" (IGEV-Stereo)",
        ));
    };
    let in_file = |reason: String| Error::config(KEY, format!("{}: {reason}", weights.display()));
    if !weights.is_file() {
        return Err(in_file("no such file".into()));
    }
    let result = load_trunk(&mut encoders.feature, weights).map_err(in_file)?;
    if let Some(error) = result.errors.first() {
        return Err(in_file(error_message(error)));
    }
    // In the trunk's order, so that the first one named is the first the file lacks.
    let mut lacking: Vec<(usize, String)> = result
        .missing
        .iter()
        .filter_map(|(path, _)| Some((TRUNK.iter().position(|t| path.starts_with(t))?, timm_key(path))))
        .collect();
    lacking.sort();
    let lacking: Vec<String> = lacking.into_iter().map(|(_, key)| key).collect();
    if let Some(first) = lacking.first() {
        return Err(in_file(format!(
            "missing key '{first}' (and {} more of the trunk): not a timm mobilenetv2_100 state dict (keys \
             conv_stem.*, bn1.*, blocks.0-5.*; a whole IGEV-Stereo checkpoint goes to train.init)",
            lacking.len() - 1
        )));
    }
    let notice = format!(
        "{KEY}: {} tensors of {} loaded into the MobileNetV2 trunk; its decoder keeps its initialisation, {} \
         key(s) of the file ignored (stage 6, the head, num_batches_tracked)",
        result.applied.len(),
        weights.display(),
        result.unused.len()
    );
    Ok((model, notice))
}

/// Loads the tensors of `weights` (`.safetensors`, else a PyTorch pickle) that the trunk has,
/// their timm keys renamed to the trunk's paths.
fn load_trunk(network: &mut MobileNetPyramid, weights: &Path) -> std::result::Result<ApplyResult, String> {
    let renames = load_patterns(TIMM_MOBILENET_TRUNK);
    if weights.extension().is_some_and(|e| e == "safetensors") {
        let mut store = SafetensorsStore::from_file(weights)
            .with_from_adapter(PyTorchToBurnAdapter)
            .map_indices_contiguous(false)
            .allow_partial(true)
            .validate(false);
        for (from, to) in &renames {
            store = store.with_key_remapping(from, to);
        }
        apply(network, &mut store)
    } else {
        let mut store =
            PytorchStore::from_file(weights).map_indices_contiguous(false).allow_partial(true).validate(false);
        for (from, to) in &renames {
            store = store.with_key_remapping(from, to);
        }
        apply(network, &mut store)
    }
}

fn apply<S: ModuleStore>(network: &mut MobileNetPyramid, store: &mut S) -> std::result::Result<ApplyResult, String>
where
    S::Error: std::fmt::Display,
{
    network.load_from(store).map_err(|e| format!("cannot read the file: {e}"))
}

/// What a failed tensor says, naming its timm key.
fn error_message(error: &ApplyError) -> String {
    match error {
        ApplyError::ShapeMismatch { path, expected, found } => format!(
            "key '{}' has shape {:?}, mobilenetv2_100 has {:?}: not a timm mobilenetv2_100 state dict",
            timm_key(path),
            found.to_vec(),
            expected.to_vec()
        ),
        ApplyError::DTypeMismatch { path, expected, found } => {
            format!("key '{}' has dtype {found:?}, expected {expected:?}", timm_key(path))
        }
        ApplyError::AdapterError { path, message } | ApplyError::LoadError { path, message } => {
            format!("key '{}': {message}", timm_key(path))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::timm_key;

    /// IGEV-Stereo's `layers = [1, 2, 3, 5, 6]`: `block3` holds stages 3 and 4, `block4` stage 5.
    #[test]
    fn trunk_paths_name_their_timm_stage() {
        assert_eq!(timm_key("block0.0.0.conv_dw.weight"), "blocks.0.0.conv_dw.weight");
        assert_eq!(timm_key("block2.0.2.bn3.running_var"), "blocks.2.2.bn3.running_var");
        assert_eq!(timm_key("block3.0.3.conv_pwl.weight"), "blocks.3.3.conv_pwl.weight");
        assert_eq!(timm_key("block3.1.0.conv_pw.weight"), "blocks.4.0.conv_pw.weight");
        assert_eq!(timm_key("block4.0.1.bn1.weight"), "blocks.5.1.bn1.weight");
        assert_eq!(timm_key("conv_stem.weight"), "conv_stem.weight");
        assert_eq!(timm_key("deconv8_4.conv.weight"), "deconv8_4.conv.weight");
    }
}
