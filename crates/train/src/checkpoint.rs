//! Training checkpoints: one safetensors file per saved step, written atomically.
//!
//! A checkpoint holds the model's tensors under their module paths (as the model crate's own
//! files), the AdamW state as one `u8` tensor [`OPTIMIZER_KEY`] (burn-optim's burnpack bytes), and
//! in the metadata: the step, the schedule, the seed (all randomness derives from the seed and the
//! step, see [`crate::batch`]), the map from parameter path to optimiser identity, the model
//! config as JSON and the resolved experiment TOML. With `train.ema_decay`, the model's keys hold
//! the moving average and the raw trained weights follow under [`RAW_WEIGHTS_PREFIX`] (the
//! metadata `ema_decay` says so), so weight readers get the average and resuming gets both
//! ([`crate::ema`]).
//!
//! Writing is atomic: the bytes go to a hidden temporary file in the same folder, which is
//! flushed to disk (`fsync`) and then renamed over the final name, so a reader sees the previous
//! file or the complete new one, never a partial one. A run killed between write and rename
//! leaves only a temporary file, which [`list_checkpoints`] ignores.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};

use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Bytes;
use dgstereo_core::atomic_file::commit_file;
use dgstereo_core::{Error, Result};
use dgstereo_model::RaftStereo;
use dgstereo_model::checkpoint::TRAINING_STATE_PREFIX;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};

use crate::ema::{Ema, RAW_WEIGHTS_PREFIX};
use crate::params::{assign_param_ids, param_ids};
use crate::trainer::{TrainParts, Trainer, adamw, init_model};

/// The tensor holding the optimiser state.
pub const OPTIMIZER_KEY: &str = "__train__.optimizer_burnpack";
/// The metadata key naming the file format.
pub const FORMAT_KEY: &str = "format";
/// The format this module writes.
pub const FORMAT: &str = "dgstereo-train-checkpoint/1";

/// The file name of the checkpoint after `step` steps.
pub fn checkpoint_name(step: usize) -> String {
    format!("step-{step:08}.safetensors")
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, committed by [`commit_file`]
/// (`fsync`, rename, folder `fsync`).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .ok_or_else(|| Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path")))?;
    let tmp = dir.join(format!(".{}.tmp", name.to_string_lossy()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
        f.write_all(bytes).map_err(|e| Error::io(&tmp, e))?;
        drop(f);
        commit_file(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The checkpoints in `dir` as `(step, path)`, oldest first; temporary files are ignored.
pub fn list_checkpoints(dir: &Path) -> Result<Vec<(usize, PathBuf)>> {
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if let Some(step) =
            name.strip_prefix("step-").and_then(|s| s.strip_suffix(".safetensors")).and_then(|s| s.parse().ok())
            && path.is_file()
        {
            found.push((step, path));
        }
    }
    found.sort();
    Ok(found)
}

/// Removes all but the newest `keep` checkpoints of `dir`.
pub fn prune_checkpoints(dir: &Path, keep: usize) -> Result<()> {
    let all = list_checkpoints(dir)?;
    for (_, path) in all.iter().take(all.len().saturating_sub(keep)) {
        std::fs::remove_file(path).map_err(|e| Error::io(path, e))?;
    }
    Ok(())
}

/// The safetensors bytes of `model`'s tensors under their module paths.
fn tensor_bytes(model: &RaftStereo) -> Result<Vec<u8>> {
    let fail = |m: String| Error::encode("the checkpoint", m);
    let (from, to) = dgstereo_model::official_keys::TO_FILE;
    let mut store = SafetensorsStore::from_bytes(None).with_key_remapping(from, to);
    model.save_into(&mut store).map_err(|e| fail(e.to_string()))?;
    store.get_bytes().map_err(|e| fail(e.to_string()))
}

/// The bytes of a checkpoint of `trainer`.
pub fn checkpoint_bytes(trainer: &Trainer) -> Result<Vec<u8>> {
    let fail = |m: String| Error::encode("the checkpoint", m);
    let model_bytes = tensor_bytes(&trainer.shipped_model())?;
    let parsed = SafeTensors::deserialize(&model_bytes).map_err(|e| fail(e.to_string()))?;
    // With EMA the model keys hold the average; the trained weights go under the prefix.
    let raw_bytes = trainer.ema.as_ref().map(|_| tensor_bytes(&trainer.inference_model())).transpose()?;
    let raw = raw_bytes.as_deref().map(SafeTensors::deserialize).transpose().map_err(|e| fail(e.to_string()))?;
    let optimizer = trainer.optimizer.into_bytes().map_err(|e| fail(format!("optimizer state: {e}")))?;
    let optimizer: &[u8] = &optimizer;
    let mut views: Vec<(String, TensorView<'_>)> = parsed.tensors();
    if let Some(raw) = &raw {
        views.extend(raw.tensors().into_iter().map(|(name, view)| (format!("{RAW_WEIGHTS_PREFIX}{name}"), view)));
    }
    views.push((
        OPTIMIZER_KEY.to_string(),
        TensorView::new(Dtype::U8, vec![optimizer.len()], optimizer).map_err(|e| fail(e.to_string()))?,
    ));
    let parts = &trainer.parts;
    let mut meta: HashMap<String, String> = HashMap::new();
    meta.insert(FORMAT_KEY.into(), FORMAT.into());
    meta.insert("step".into(), trainer.step.to_string());
    meta.insert("seed".into(), parts.train.seed.to_string());
    meta.insert(
        "rng".into(),
        format!(
            "{{\"kind\":\"stateless\",\"seed\":{},\"next_step\":{},\"note\":\"data, augmentation and prior draws of step k derive from (seed, k)\"}}",
            parts.train.seed, trainer.step
        ),
    );
    meta.insert("schedule".into(), to_json(&trainer.schedule));
    meta.insert("param_ids".into(), to_json(&param_ids(&trainer.model)));
    meta.insert("model_config".into(), to_json(&parts.model));
    meta.insert("config".into(), parts.resolved_toml.clone());
    meta.insert("name".into(), parts.name.clone());
    if let Some(ema) = &trainer.ema {
        meta.insert("ema_decay".into(), ema.decay().to_string());
    }
    let bytes = safetensors::serialize(views, &Some(meta)).map_err(|e| fail(e.to_string()))?;
    dgstereo_model::canonical_safetensors::canonical_header(&bytes)
}

/// A value as a JSON string (plain configuration data always serialises).
fn to_json<T: serde::Serialize>(value: &T) -> String {
    serde_json::to_string(value).expect("plain data serialises")
}

/// Writes the checkpoint of `trainer` into `dir` (atomically) and keeps the newest `keep`.
pub fn save_checkpoint(trainer: &Trainer, dir: &Path, keep: usize) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let path = dir.join(checkpoint_name(trainer.step));
    // Never replace good checkpoints with non-finite weights.
    dgstereo_model::checkpoint::check_finite(&trainer.inference_model(), &path)?;
    if trainer.ema.is_some() {
        dgstereo_model::checkpoint::check_finite(&trainer.shipped_model(), &path)?;
    }
    write_atomic(&path, &checkpoint_bytes(trainer)?)?;
    prune_checkpoints(dir, keep)?;
    Ok(path)
}

/// The metadata of a checkpoint.
pub fn read_metadata(path: &Path) -> Result<BTreeMap<String, String>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (_, meta) =
        SafeTensors::read_metadata(&bytes).map_err(|e| Error::format(path, format!("not a safetensors file: {e}")))?;
    Ok(meta.metadata().clone().unwrap_or_default().into_iter().collect())
}

/// Restores a run from a checkpoint written by [`save_checkpoint`]: weights, parameter
/// identities, optimiser state, step and, with `train.ema_decay`, the moving average. `parts`
/// must build the same network.
///
/// A checkpoint saved without EMA resumed with `ema_decay` set starts the average at its
/// weights; one saved with EMA resumed without it continues from its raw trained weights. Both
/// print a notice.
pub fn load_checkpoint(parts: TrainParts, path: &Path, device: &burn::tensor::Device) -> Result<Trainer> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |m: String| Error::Checkpoint { path: path.into(), message: m };
    let parsed =
        SafeTensors::deserialize(&bytes).map_err(|e| bad(format!("not a safetensors file (truncated?): {e}")))?;
    let (_, header) = SafeTensors::read_metadata(&bytes).map_err(|e| bad(e.to_string()))?;
    let meta = header.metadata().clone().unwrap_or_default();
    if meta.get(FORMAT_KEY).map(String::as_str) != Some(FORMAT) {
        return Err(bad(format!("not a training checkpoint (metadata '{FORMAT_KEY}' is not '{FORMAT}')")));
    }
    let get = |k: &str| meta.get(k).ok_or_else(|| bad(format!("metadata '{k}' is missing")));
    let step: usize = get("step")?.parse().map_err(|e| bad(format!("metadata 'step': {e}")))?;
    let ids: BTreeMap<String, u64> =
        serde_json::from_str(get("param_ids")?).map_err(|e| bad(format!("metadata 'param_ids': {e}")))?;
    let saved_model = dgstereo_model::ModelConfig::from_checkpoint_json(get("model_config")?)
        .map_err(|e| bad(format!("metadata 'model_config': {e}")))?;
    if saved_model != parts.model {
        return Err(bad("the checkpoint was trained with another [model] configuration than the experiment's".into()));
    }
    let optimizer = parsed.tensor(OPTIMIZER_KEY).map_err(|e| bad(format!("tensor '{OPTIMIZER_KEY}': {e}")))?;
    let optimizer = adamw(&parts.train)
        .from_bytes(Bytes::from_bytes_vec(optimizer.data().to_vec()))
        .map_err(|e| bad(format!("optimizer state: {e}")))?;

    // With EMA the model keys hold the average and the trained weights are under the prefix.
    let raw: Vec<(String, TensorView<'_>)> = parsed
        .tensors()
        .into_iter()
        .filter_map(|(name, view)| name.strip_prefix(RAW_WEIGHTS_PREFIX).map(|n| (n.to_string(), view)))
        .collect();
    let saved_with_ema = !raw.is_empty();
    let model = if saved_with_ema {
        let raw_bytes = safetensors::serialize(raw, &None).map_err(|e| bad(format!("raw weights: {e}")))?;
        read_model(&parts, raw_bytes, path, device)?
    } else {
        read_model(&parts, bytes.clone(), path, device)?
    };
    let (model, missing) = assign_param_ids(model, &ids);
    if let Some(p) = missing.first() {
        return Err(bad(format!("no optimiser identity for parameter '{p}'")));
    }
    let mut trainer = Trainer::with_model(parts, model, device, optimizer, step)?;
    match (trainer.parts.train.ema_decay, saved_with_ema) {
        (Some(decay), true) => trainer.ema = Some(Ema::new(decay, read_model(&trainer.parts, bytes, path, device)?)),
        (Some(_), false) => trainer.notices.push(format!(
            "{}: saved without train.ema_decay; the moving average of the weights starts at its weights (step {step})",
            path.display()
        )),
        (None, true) => trainer.notices.push(format!(
            "{}: saved with train.ema_decay, which is no longer set; continuing from its raw trained weights without a moving average",
            path.display()
        )),
        (None, false) => {}
    }
    Ok(trainer)
}

/// The model of `parts` with the weights of the safetensors `bytes` (read from `path`) under
/// their module paths; every weight must be there, and keys under `__train__.` are skipped.
fn read_model(parts: &TrainParts, bytes: Vec<u8>, path: &Path, device: &burn::tensor::Device) -> Result<RaftStereo> {
    let bad = |m: String| Error::Checkpoint { path: path.into(), message: m };
    let mut model = init_model(&parts.model, device, None)?;
    let (from, to) = dgstereo_model::official_keys::from_file(&model);
    let mut store =
        SafetensorsStore::from_bytes(Some(bytes)).allow_partial(true).validate(false).with_key_remapping(from, to);
    let result = model.load_from(&mut store).map_err(|e| bad(format!("cannot read the weights: {e}")))?;
    if let Some(e) = result.errors.first() {
        return Err(bad(e.to_string()));
    }
    if let Some((k, _)) = result.missing.first() {
        return Err(bad(format!("missing weight '{k}' ({} in all)", result.missing.len())));
    }
    if let Some(k) = result.unused.iter().find(|k| !k.starts_with(TRAINING_STATE_PREFIX)) {
        return Err(bad(format!("unknown weight '{k}'")));
    }
    dgstereo_model::checkpoint::check_finite(&model, path)?;
    Ok(model)
}

#[cfg(test)]
mod tests {
    #[test]
    fn training_state_is_under_the_prefix_weight_loading_skips() {
        assert!(super::OPTIMIZER_KEY.starts_with(dgstereo_model::checkpoint::TRAINING_STATE_PREFIX));
        assert!(crate::ema::RAW_WEIGHTS_PREFIX.starts_with(dgstereo_model::checkpoint::TRAINING_STATE_PREFIX));
    }
}
