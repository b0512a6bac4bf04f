//! What the conformance checks on seeded goldens share (`verify_defom`, `verify_igev`): the
//! network rebuilt from a golden's metadata and loaded as an official checkpoint, and its pass
//! over the golden's inputs with every stage's output traced.

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::Device;
use dgstereo_core::{Error, Result};

use crate::checkpoint_config::{self, CheckpointConfig};
use crate::official_keys::KeyShape;
use crate::seeded::golden_state_dict;
use crate::verify::{ReferenceTensors, read_reference, tensor4};
use crate::{ForwardOptions, Probe, RaftStereo, Trace, checkpoint};

/// A seeded golden's network: its configuration read from the keys and shapes alone, the model
/// with the seeded weights loaded through the official-checkpoint loader, the file's metadata
/// and its iteration count.
pub(crate) struct SeededModel {
    /// What the keys and shapes show.
    pub(crate) config: CheckpointConfig,
    /// The network with the seeded weights.
    pub(crate) model: RaftStereo,
    /// The golden's metadata (`iters`, `scale_iters`, ...).
    pub(crate) metadata: BTreeMap<String, String>,
    /// The iterations the official code ran (`iters`).
    pub(crate) iters: usize,
}

/// The network of the seeded golden `reference` ([`SeededModel`]).
///
/// # Errors
/// [`Error::Io`], [`Error::Format`] when the file cannot be read or lacks what a seeded golden
/// holds; [`Error::Checkpoint`] when its keys match no configuration or do not load.
pub(crate) fn load_seeded(reference: &Path, device: &Device) -> Result<SeededModel> {
    let (state, metadata) = golden_state_dict(reference)?;
    let keys: Vec<KeyShape> = state.iter().map(|t| (t.key.clone(), t.shape.clone())).collect();
    let (config, model) = checkpoint_config::model_from_keys(&keys, device)
        .map_err(|p| Error::Checkpoint { path: reference.into(), message: p.to_string() })?;
    let model = checkpoint::load_state_dict(model, &state, reference)?;
    let iters = metadata_count(&metadata, "iters", reference)?;
    Ok(SeededModel { config, model, metadata, iters })
}

/// `model`'s pass over the inputs of `reference` (`input.left`, `input.right`) for `iters`
/// iterations, every iteration upsampled, with the file's tensors and the pass's trace.
///
/// # Errors
/// [`Error::Format`] when the file lacks its inputs; the pass's own errors.
pub(crate) fn traced_pass(
    model: &RaftStereo,
    reference: &Path,
    iters: usize,
    device: &Device,
) -> Result<(ReferenceTensors, Trace)> {
    let refs = read_reference(reference)?;
    let left = tensor4(&refs, "input.left", reference, device)?;
    let right = tensor4(&refs, "input.right", reference, device)?;
    let mut trace = BTreeMap::new();
    let options =
        ForwardOptions { all_iterations: true, probe: Probe::new(Some(&mut trace), None), ..ForwardOptions::default() };
    model.forward_flow(left, right, None, iters, options)?;
    Ok((refs, trace))
}

/// The count a golden's metadata entry `name` holds.
///
/// # Errors
/// [`Error::Format`] naming the entry when it is missing or no count.
pub(crate) fn metadata_count(metadata: &BTreeMap<String, String>, name: &str, path: &Path) -> Result<usize> {
    let text = metadata.get(name).ok_or_else(|| Error::format(path, format!("no metadata entry '{name}'")))?;
    text.parse().map_err(|_| Error::format(path, format!("metadata entry '{name}' = '{text}' is not a count")))
}
