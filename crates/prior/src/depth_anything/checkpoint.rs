//! Loading official Depth Anything V2 checkpoints (`depth_anything_v2_vit{s,b,l}.pth`).
//!
//! burn-store's [`PytorchStore`] reads the pickle and transposes `Linear` weights. The module's
//! field names are the checkpoint's own except for four PyTorch names that are not Rust
//! identifiers or index an `nn.Sequential`/`nn.ModuleList` with gaps; [`KEY_RENAMES`] maps those
//! both ways, in core's key notation, and is the one copy of them: the model crate reads it for
//! DEFOM-Stereo's Depth Anything V2. Index renumbering is off (`map_indices_contiguous(false)`): `resize_layers.{0,1,3}`
//! and `output_conv2.{0,2}` would otherwise be silently shifted. Loading is strict: every
//! checkpoint key must land in the module and every module parameter must come from the
//! checkpoint, with the same shape; otherwise the error names the checkpoint key.

use std::path::Path;

use std::sync::LazyLock;

use burn::store::{ApplyError, BurnToPyTorchAdapter, KeyRemapper, ModuleSnapshot, ModuleStore, PytorchStore};
use dgstereo_core::key_notation::{Rename, apply, load_patterns, save_patterns};
use dgstereo_core::{Error, Problem, Result};

use super::encoder::DepthAnythingV2Encoder;

/// The keys whose PyTorch names are not field names, checkpoint fragment to module fragment: the
/// DPT heads' (`depth_head`, and DEFOM-Stereo's `depth_feat` built of the same blocks).
pub const KEY_RENAMES: &[Rename] = &[
    Rename::new("{depth_head|depth_feat}.resize_layers.0.", "{depth_head|depth_feat}.upsample_4x."),
    Rename::new("{depth_head|depth_feat}.resize_layers.1.", "{depth_head|depth_feat}.upsample_2x."),
    Rename::new("{depth_head|depth_feat}.resize_layers.3.", "{depth_head|depth_feat}.downsample_2x."),
    Rename::new("scratch.output_conv2.0.", "scratch.output_conv2_hidden."),
    Rename::new("scratch.output_conv2.2.", "scratch.output_conv2_out."),
    Rename::new(".resConfUnit{1|2}.", ".res_conf_unit{1|2}."),
];

static TO_MODULE: LazyLock<KeyRemapper> = LazyLock::new(|| {
    KeyRemapper::from_patterns(load_patterns(KEY_RENAMES)).expect("the notation makes valid patterns")
});
static TO_CHECKPOINT: LazyLock<KeyRemapper> = LazyLock::new(|| {
    KeyRemapper::from_patterns(save_patterns(KEY_RENAMES)).expect("the notation makes valid patterns")
});

/// The module path of a checkpoint key.
pub fn module_key(checkpoint_key: &str) -> String {
    apply(&TO_MODULE, checkpoint_key)
}

/// The checkpoint key of a module path (inverse of [`module_key`]).
pub fn checkpoint_key(module_key: &str) -> String {
    apply(&TO_CHECKPOINT, module_key)
}

fn checkpoint_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Checkpoint { path: path.to_path_buf(), message: message.into() }
}

fn open_store(weights: &Path) -> Result<PytorchStore> {
    if !weights.is_file() {
        return Err(Error::io(weights, std::io::Error::new(std::io::ErrorKind::NotFound, "checkpoint not found")));
    }
    let mut store = PytorchStore::from_file(weights).map_indices_contiguous(false).allow_partial(true).validate(false);
    for (from, to) in load_patterns(KEY_RENAMES) {
        store = store.with_key_remapping(from, to);
    }
    Ok(store)
}

/// Loads every tensor of `weights` into `model`, a network of size `encoder`.
///
/// # Errors
/// [`Error::Io`] when the file is missing; [`Error::Checkpoint`] naming the first offending key
/// when a key is missing from the checkpoint, unknown to the model, or of the wrong shape.
pub fn load_into<M: ModuleSnapshot>(model: &mut M, encoder: DepthAnythingV2Encoder, weights: &Path) -> Result<()> {
    let mut store = open_store(weights)?;
    let result = model.load_from(&mut store).map_err(|e| checkpoint_error(weights, e.to_string()))?;
    if let Some(error) = result.errors.first() {
        return Err(checkpoint_error(weights, apply_error_message(error, encoder)));
    }
    if let Some((path, _)) = result.missing.first() {
        return Err(checkpoint_error(
            weights,
            format!(
                "missing key '{}' (and {} more) for the {} model",
                checkpoint_key(path),
                result.missing.len() - 1,
                encoder
            ),
        ));
    }
    if let Some(path) = result.unused.first() {
        return Err(checkpoint_error(
            weights,
            format!(
                "unknown key '{}' (and {} more) for the {} model",
                checkpoint_key(path),
                result.unused.len() - 1,
                encoder
            ),
        ));
    }
    Ok(())
}

/// What the first error of a load says, naming the checkpoint key.
fn apply_error_message(error: &ApplyError, encoder: DepthAnythingV2Encoder) -> String {
    match error {
        ApplyError::ShapeMismatch { path, expected, found } => format!(
            "key '{}' has shape {:?}, the {} model expects {:?}",
            checkpoint_key(path),
            found.to_vec(),
            encoder,
            expected.to_vec()
        ),
        ApplyError::DTypeMismatch { path, expected, found } => {
            format!("key '{}' has dtype {found:?}, expected {expected:?}", checkpoint_key(path))
        }
        ApplyError::AdapterError { path, message } | ApplyError::LoadError { path, message } => {
            format!("key '{}': {message}", checkpoint_key(path))
        }
    }
}

/// What [`load_partial_into`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PartialLoad {
    /// Parameters loaded from the file (module paths).
    pub loaded: usize,
    /// Parameters the file lacks, which keep their values (checkpoint keys).
    pub kept: Vec<String>,
    /// Keys of the file the module lacks, ignored.
    pub ignored: Vec<String>,
}

/// Loads the tensors of `weights` that `model` has, as PyTorch's `load_state_dict(strict=False)`
/// does: keys the module lacks are ignored and parameters the file lacks keep their values, but
/// a tensor of another shape is an error. Every parameter whose checkpoint key starts with one
/// of `required` (`"pretrained."`) must come from the file.
///
/// # Errors
/// [`Error::Io`] when the file is missing; [`Error::Checkpoint`] naming the first key of the
/// wrong shape or dtype, or the first required key the file lacks.
pub fn load_partial_into<M: ModuleSnapshot>(
    model: &mut M,
    encoder: DepthAnythingV2Encoder,
    weights: &Path,
    required: &[&str],
) -> Result<PartialLoad> {
    let mut store = open_store(weights)?;
    let result = model.load_from(&mut store).map_err(|e| checkpoint_error(weights, e.to_string()))?;
    if let Some(error) = result.errors.first() {
        return Err(checkpoint_error(weights, apply_error_message(error, encoder)));
    }
    let mut kept: Vec<String> = result.missing.iter().map(|(path, _)| checkpoint_key(path)).collect();
    kept.sort();
    let lacking: Vec<&String> = kept.iter().filter(|k| required.iter().any(|r| k.starts_with(r))).collect();
    if let Some(first) = lacking.first() {
        return Err(checkpoint_error(
            weights,
            format!(
                "missing key '{first}' (and {} more of {}) for the {encoder} model: not a Depth Anything V2 \
                 {encoder} checkpoint?",
                lacking.len() - 1,
                required.join(", ")
            ),
        ));
    }
    let ignored = result.unused.iter().map(|path| checkpoint_key(path)).collect();
    Ok(PartialLoad { loaded: result.applied.len(), kept, ignored })
}

/// The checkpoint's keys with their shapes, sorted by key.
pub fn checkpoint_keys(weights: &Path) -> Result<Vec<(String, Vec<usize>)>> {
    let mut store = open_store(weights)?;
    let tensors = store.get_all_tensors().map_err(|e| checkpoint_error(weights, e.to_string()))?;
    Ok(tensors.iter().map(|(k, t)| (checkpoint_key(k), t.shape.to_vec())).collect())
}

/// The checkpoint keys and shapes of `model`'s parameters, sorted by key: the state dict an
/// official checkpoint of the same size holds (PyTorch's names and layouts, as burn-store
/// writes them for PyTorch).
pub fn model_keys<M: ModuleSnapshot>(model: &M) -> Vec<(String, Vec<usize>)> {
    let tensors = model.collect(None, Some(Box::new(BurnToPyTorchAdapter)), false);
    let mut keys: Vec<_> = tensors.iter().map(|t| (checkpoint_key(&t.name), t.shape.to_vec())).collect();
    keys.sort();
    keys
}

/// The encoder size of a checkpoint, from the width of `pretrained.cls_token`, the number of
/// blocks and the DPT head's widths ([`encoder_from_keys`]).
pub fn detect_encoder(weights: &Path) -> Result<DepthAnythingV2Encoder> {
    encoder_from_keys(&checkpoint_keys(weights)?).map_err(|p| checkpoint_error(weights, p.to_string()))
}

/// The encoder size whose state dict `keys` (checkpoint keys with shapes) is: the token width
/// (`pretrained.cls_token`) names the size; the block count (`pretrained.blocks.*`), the head's
/// projections (`depth_head.projects.{i}.weight`: the four `out_channels`) and its fusion width
/// (`depth_head.scratch.layer1_rn.weight`: `features`) must be that size's.
///
/// # Errors
/// A [`Problem`] keyed by the first checkpoint key that is missing or disagrees.
pub fn encoder_from_keys(keys: &[(String, Vec<usize>)]) -> std::result::Result<DepthAnythingV2Encoder, Problem> {
    let shape = |key: &str| keys.iter().find(|(k, _)| k == key).map(|(_, s)| s.as_slice());
    let missing = |key: &str| Problem::new(key, "missing");
    let cls = shape("pretrained.cls_token").ok_or_else(|| missing("pretrained.cls_token"))?;
    let width = *cls.last().unwrap_or(&0);
    let encoder = DepthAnythingV2Encoder::from_embed_dim(width)
        .ok_or_else(|| Problem::new("pretrained.cls_token", format!("has width {width}, not one of vits/vitb/vitl")))?;
    let blocks =
        keys.iter().filter(|(k, _)| k.starts_with("pretrained.blocks.") && k.ends_with(".norm1.weight")).count();
    if blocks != encoder.vit().depth {
        let reason = format!("{blocks} blocks, the {encoder} encoder has {}", encoder.vit().depth);
        return Err(Problem::new("pretrained.blocks.*", reason));
    }
    for (i, channels) in encoder.out_channels().into_iter().enumerate() {
        let key = format!("depth_head.projects.{i}.weight");
        match shape(&key) {
            Some(s) if s.first() == Some(&channels) => {}
            Some(s) => {
                let reason = format!("has shape {s:?}, the {encoder} encoder projects to {channels}");
                return Err(Problem::new(key, reason));
            }
            None => return Err(missing(&key)),
        }
    }
    let key = "depth_head.scratch.layer1_rn.weight";
    match shape(key) {
        Some(s) if s.first() == Some(&encoder.features()) => Ok(encoder),
        Some(s) => Err(Problem::new(
            key,
            format!("has shape {s:?}, the {encoder} encoder's head has {} features", encoder.features()),
        )),
        None => Err(missing(key)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_renames_round_trip() {
        for key in [
            "depth_head.resize_layers.3.weight",
            "depth_head.scratch.refinenet2.resConfUnit1.conv2.bias",
            "depth_head.scratch.output_conv2.2.weight",
            "pretrained.blocks.7.ls1.gamma",
        ] {
            assert_eq!(checkpoint_key(&module_key(key)), key);
        }
        assert_eq!(module_key("depth_head.resize_layers.0.bias"), "depth_head.upsample_4x.bias");
        assert_eq!(
            module_key("depth_head.scratch.refinenet4.resConfUnit2.conv1.weight"),
            "depth_head.scratch.refinenet4.res_conf_unit2.conv1.weight"
        );
    }
}
