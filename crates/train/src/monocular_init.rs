//! `train.monocular_init`: Depth Anything V2 weights in the stereo network's monocular network
//! before training, as DEFOM-Stereo's `DefomEncoder` loads `depth_anything_v2_vit{s,l}.pth`.
//!
//! The official code loads the file with `strict=False`: its feature trunk (`depth_feat`) is not
//! in a Depth Anything V2 checkpoint and starts from its initialisation. Here the ViT and the
//! depth head must come from the file whole (they are frozen in DEFOM's recipe, so a tensor
//! missing there would stay random for the whole run), and a file that does not fit is an error
//! naming `train.monocular_init`, the file and the key.

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_model::RaftStereo;

/// The key the errors name.
const KEY: &str = "train.monocular_init";

/// `model` with the Depth Anything V2 weights of `weights` in its monocular network, and a
/// notice of what the file did not hold.
///
/// # Errors
/// [`Error::Config`] keyed `train.monocular_init` when the model has no monocular network, or
/// the file is missing, of another size, or lacks a ViT or depth-head tensor (the message
/// names the file and the key).
pub fn load_monocular_init(mut model: RaftStereo, weights: &Path) -> Result<(RaftStereo, String)> {
    let Some(network) = model.monocular.as_mut() else {
        return Err(Error::config(
            KEY,
            "the model has no monocular network to load into: set model.monocular (kind = \"depth-anything-v2\")",
        ));
    };
    let load = network.load_depth_anything(weights).map_err(|e| Error::config(KEY, e.to_string()))?;
    let notice = format!(
        "{KEY}: {} tensors of {} loaded into the monocular network; {} parameter(s) it lacks keep their \
         initialisation (the feature trunk), {} key(s) of the file ignored",
        load.loaded,
        weights.display(),
        load.kept.len(),
        load.ignored.len()
    );
    Ok((model, notice))
}
