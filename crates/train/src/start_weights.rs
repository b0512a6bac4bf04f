//! The weights a fresh run starts from, after its seeded initialisation: the pretrained parts
//! first (`train.monocular_init`: Depth Anything V2 in the monocular network, DEFOM-Stereo's;
//! `train.feature_init`: ImageNet MobileNetV2 in the feature trunk, IGEV-Stereo's), then the whole
//! network's `train.init`, as the official scripts build the pretrained modules and then restore a
//! checkpoint over them.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use dgstereo_experiment::TrainingConfig;
use dgstereo_model::RaftStereo;

use crate::feature_init::load_feature_init;
use crate::monocular_init::load_monocular_init;

/// A loader of a pretrained part: the model with the file's weights in that part, and a notice.
type PartLoader = fn(RaftStereo, &Path) -> Result<(RaftStereo, String)>;

/// `model` with the weights `train` names loaded, in order, and a notice of each load for the
/// user.
///
/// # Errors
/// [`Error::Config`] keyed by the first key whose file does not fit (`train.monocular_init`,
/// `train.feature_init`, `train.init`).
pub fn load_start_weights(mut model: RaftStereo, train: &TrainingConfig) -> Result<(RaftStereo, Vec<String>)> {
    let mut notices = Vec::new();
    let pretrained: [(&Option<PathBuf>, PartLoader); 2] =
        [(&train.monocular_init, load_monocular_init), (&train.feature_init, load_feature_init)];
    for (weights, load) in pretrained {
        if let Some(weights) = weights {
            let (loaded, notice) = load(model, weights)?;
            notices.push(notice);
            model = loaded;
        }
    }
    let model = match &train.init {
        Some(path) => {
            let (model, missing) = dgstereo_model::checkpoint::load_weights(model, path, train.init_strict)
                .map_err(|e| Error::config("train.init", e.to_string()))?;
            if !missing.is_empty() {
                notices.push(format!(
                    "train.init: {} parameter(s) not in {} keep their initialisation (e.g. {})",
                    missing.len(),
                    path.display(),
                    missing.iter().take(3).cloned().collect::<Vec<_>>().join(", ")
                ));
            }
            model
        }
        None => model,
    };
    Ok((model, notices))
}
