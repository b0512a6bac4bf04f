//! Loading official RAFT-Stereo checkpoints and saving/loading our own.
//!
//! Official `.pth` files (`raftstereo-*.pth`, saved from `DataParallel`, keys prefixed
//! `module.`; DEFOM-Stereo's `defomstereo_*.pth`) load directly through burn-store's PyTorch
//! reader, into a model built with the checkpoint's configuration ([`crate::checkpoint_config`]
//! reads it from the tensors), their keys renamed to our paths and the keys the reference stores
//! twice or as constants ignored, as the model family's table says
//! ([`crate::official_keys::renames`]). Any other unknown key, any missing key and any shape mismatch is an error naming the
//! key, and non-finite weights are refused. A state dict held in memory (the seeded weights of a
//! conformance file, [`crate::seeded`]) goes through the same renames and checks
//! ([`load_state_dict`]). Our own checkpoints are safetensors with the resolved config in the
//! metadata.

use std::path::Path;

use burn::store::burn_pack::Tensor as PackTensor;
use burn::store::{
    ApplyError, ApplyResult, KeyRemapper, ModuleSnapshot, PyTorchToBurnAdapter, PytorchStore, SafetensorsStore, bridge,
};
use burn::tensor::TensorData;
use dgstereo_core::atomic_file::commit_file;
use dgstereo_core::{Error, Result};

use crate::RaftStereo;
use crate::official_keys::{Family, TO_FILE, from_file, ignored_by_loader};
use crate::seeded::StateDict;

/// Loads an official RAFT-Stereo `.pth` checkpoint into `model` (built with the matching config).
pub fn load_pytorch(model: RaftStereo, path: &Path) -> Result<RaftStereo> {
    load_pytorch_keys(model, path, true).map(|(m, _)| m)
}

/// [`load_pytorch`], or with `strict = false` leaving parameters the file lacks as they are;
/// returns their names.
fn load_pytorch_keys(mut model: RaftStereo, path: &Path, strict: bool) -> Result<(RaftStereo, Vec<String>)> {
    if !path.is_file() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file")));
    }
    let mut store = PytorchStore::from_file(path).map_indices_contiguous(false).allow_partial(true).validate(false);
    for (from, to) in Family::of(&model).load_patterns() {
        store = store.with_key_remapping(from, to);
    }
    let result = model
        .load_from(&mut store)
        .map_err(|e| Error::Checkpoint { path: path.into(), message: format!("cannot read checkpoint: {e}") })?;
    check_official(model, result, path, strict)
}

/// Loads a state dict in the official layout held in memory (the seeded weights of a
/// conformance file, [`crate::seeded::golden_state_dict`]) into `model`, through the same
/// renames and checks as an official `.pth` file (strict: every key must land, every parameter
/// come from it); `origin` names it in errors.
///
/// # Errors
/// [`Error::Checkpoint`] naming `origin` and the keys that are missing, unknown, mis-shaped or
/// not finite.
pub fn load_state_dict(mut model: RaftStereo, state: &StateDict, origin: &Path) -> Result<RaftStereo> {
    let tensors: Vec<PackTensor> = state
        .iter()
        .map(|t| bridge::from_data(TensorData::new(t.values.clone(), t.shape.clone()), t.key.clone(), None))
        .collect();
    let renames = KeyRemapper::from_patterns(Family::of(&model).load_patterns())
        .expect("the renames' notation makes valid patterns");
    let (tensors, _) = renames.remap(tensors);
    // As the PyTorch store applies a file's tensors: PyTorch's layouts, enum variants skipped.
    let result = model.apply(tensors, None, Some(Box::new(PyTorchToBurnAdapter)), true);
    check_official(model, result, origin, true).map(|(m, _)| m)
}

/// What a load of the official layout into `model` left: an error naming the keys that did not
/// land (all of them strictly; else only keys unknown to the model and errors other than shape
/// mismatches), or the model with the parameters it kept from its initialisation.
fn check_official(
    model: RaftStereo,
    result: ApplyResult,
    path: &Path,
    strict: bool,
) -> Result<(RaftStereo, Vec<String>)> {
    let fail = |message: String| Err(Error::Checkpoint { path: path.into(), message });
    let (kept, errors) = split_errors(&result.errors, strict);
    if let Some(e) = errors.first() {
        return fail(format!("{e} ({} errors in all)", errors.len()));
    }
    if strict && !result.missing.is_empty() {
        let keys: Vec<&str> = result.missing.iter().map(|(k, _)| k.as_str()).take(8).collect();
        return fail(format!(
            "missing key(s) for this model configuration: {} ({} in all; is the experiment's model config the checkpoint's?)",
            keys.join(", "),
            result.missing.len()
        ));
    }
    let unknown: Vec<&str> = result.unused.iter().map(String::as_str).filter(|k| !ignored_by_loader(k)).collect();
    if !unknown.is_empty() {
        return fail(format!(
            "unknown key(s) not used by this model configuration: {} ({} in all)",
            unknown.iter().take(8).copied().collect::<Vec<_>>().join(", "),
            unknown.len()
        ));
    }
    // Convolutions whose input grew start from the file's weights on their leading channels.
    let (model, grown) = crate::grown_inputs::warm_start(model, path, &kept)?;
    let kept = kept.into_iter().filter(|k| !grown.contains(k));
    check_finite(&model, path)?;
    Ok((model, result.missing.into_iter().map(|(k, _)| k).chain(kept).collect()))
}

/// Fails with the parameter's name when any weight is NaN or infinite.
pub fn check_finite(model: &RaftStereo, path: &Path) -> Result<()> {
    for t in model.collect(None, None, true) {
        let data = burn::store::bridge::to_data(&t)
            .map_err(|e| Error::Checkpoint { path: path.into(), message: format!("{}: {e}", t.name) })?;
        let values = data.convert::<f32>().try_to_vec::<f32>().unwrap_or_default();
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(Error::Checkpoint {
                path: path.into(),
                message: format!("{}: non-finite weight ({v})", t.name),
            });
        }
    }
    Ok(())
}

/// Saves `model` as safetensors with `metadata` (e.g. the resolved config as JSON), atomically:
/// the file appears complete or not at all (written to a temporary name, then renamed).
pub fn save_safetensors(model: &RaftStereo, path: &Path, metadata: &[(&str, &str)]) -> Result<()> {
    let tmp = path.with_extension("safetensors.tmp");
    let mut store = SafetensorsStore::from_file(&tmp).overwrite(true).with_key_remapping(TO_FILE.0, TO_FILE.1);
    for (k, v) in metadata {
        store = store.metadata(*k, *v);
    }
    model
        .save_into(&mut store)
        .map_err(|e| Error::Checkpoint { path: path.into(), message: format!("cannot write: {e}") })?;
    // The store orders the metadata by hash: sort it, so equal weights make equal files.
    let bytes = std::fs::read(&tmp).map_err(|e| Error::io(&tmp, e))?;
    let canonical = crate::canonical_safetensors::canonical_header(&bytes)
        .map_err(|e| Error::Checkpoint { path: path.into(), message: e.to_string() })?;
    std::fs::write(&tmp, canonical).map_err(|e| Error::io(&tmp, e))?;
    finish_atomic(&tmp, path)
}

/// Makes the written temporary file `tmp` the file `path`: readable by all (the store creates
/// it private, 0600, where a weights file is meant to be shared like any other output), then
/// committed on disk ([`commit_file`]), so a crash leaves either the old file or the whole new one.
fn finish_atomic(tmp: &Path, path: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp, std::fs::Permissions::from_mode(0o644)).map_err(|e| Error::io(tmp, e))?;
    }
    commit_file(tmp, path)
}

/// Loads our own safetensors checkpoint into `model` (built with the config it was saved with).
pub fn load_safetensors(model: RaftStereo, path: &Path) -> Result<RaftStereo> {
    load_safetensors_keys(model, path, true).map(|(m, _)| m)
}

/// [`load_safetensors`], or with `strict = false` leaving parameters the file lacks as they are;
/// returns their names.
fn load_safetensors_keys(mut model: RaftStereo, path: &Path, strict: bool) -> Result<(RaftStereo, Vec<String>)> {
    if !path.is_file() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file")));
    }
    let (from, to) = from_file(&model);
    let mut store = SafetensorsStore::from_file(path).allow_partial(true).validate(false).with_key_remapping(from, to);
    let result = model
        .load_from(&mut store)
        .map_err(|e| Error::Checkpoint { path: path.into(), message: format!("cannot read checkpoint: {e}") })?;
    let fail = |message: String| Err(Error::Checkpoint { path: path.into(), message });
    let (kept, errors) = split_errors(&result.errors, strict);
    if let Some(e) = errors.first() {
        return fail(e.to_string());
    }
    if let Some((k, _)) = result.missing.first().filter(|_| strict) {
        return fail(format!(
            "missing key '{k}' ({} in all): the checkpoint was saved from another model configuration",
            result.missing.len()
        ));
    }
    // A training checkpoint also holds the optimiser state under `__train__.`: the model part
    // loads as weights.
    let unused: Vec<&String> = result.unused.iter().filter(|k| !k.starts_with(TRAINING_STATE_PREFIX)).collect();
    if let Some(k) = unused.first() {
        return fail(format!(
            "unknown key '{k}' ({} in all): the checkpoint was saved from another model configuration",
            unused.len()
        ));
    }
    // Convolutions whose input grew start from the file's weights on their leading channels.
    let (model, grown) = crate::grown_inputs::warm_start(model, path, &kept)?;
    let kept = kept.into_iter().filter(|k| !grown.contains(k));
    check_finite(&model, path)?;
    Ok((model, result.missing.into_iter().map(|(k, _)| k).chain(kept).collect()))
}

/// Loads weights by extension (`.pth`/`.pt`: official layout, `.safetensors`: ours, training
/// checkpoints included) into `model`. With `strict`, every parameter must be in the file with
/// its shape; otherwise parameters it lacks or holds in another shape keep their initialisation
/// and are returned by name, except (safetensors files) a convolution whose input channels grew,
/// such as the motion encoder's last one under guidance: it takes the file's weights on its
/// leading input channels and zeros on the new ones ([`crate::grown_inputs`]), so it computes
/// what it computed before. Keys the model lacks and non-finite weights are errors either way.
pub fn load_weights(model: RaftStereo, path: &Path, strict: bool) -> Result<(RaftStereo, Vec<String>)> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "pth" | "pt" => load_pytorch_keys(model, path, strict),
        "safetensors" => load_safetensors_keys(model, path, strict),
        _ => Err(Error::Checkpoint {
            path: path.into(),
            message: "unknown weights format (expected .pth, .pt or .safetensors)".into(),
        }),
    }
}

/// Splits load errors into the paths of shape mismatches a non-strict load tolerates (the
/// parameter keeps its initialisation) and the errors that remain.
fn split_errors(errors: &[ApplyError], strict: bool) -> (Vec<String>, Vec<&ApplyError>) {
    let mut kept = Vec::new();
    let mut rest = Vec::new();
    for e in errors {
        match e {
            ApplyError::ShapeMismatch { path, .. } if !strict => kept.push(path.clone()),
            other => rest.push(other),
        }
    }
    (kept, rest)
}

/// Keys under this prefix in our safetensors files hold training state, not weights.
pub const TRAINING_STATE_PREFIX: &str = "__train__.";

/// Reads a metadata entry of a safetensors file (e.g. `config`).
pub fn safetensors_metadata(path: &Path, key: &str) -> Result<Option<String>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes)
        .map_err(|e| Error::format(path, format!("not a safetensors file: {e}")))?;
    Ok(meta.metadata().as_ref().and_then(|m| m.get(key).cloned()))
}
