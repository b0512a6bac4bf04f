//! What the state dict of an official DEFOM-Stereo or IGEV-Stereo checkpoint must hold, read
//! from its keys and shapes alone (their models are built elsewhere): the module tree of the
//! official code (`core/defom_stereo.py`, `IGEV-Stereo/core/igev_stereo.py`), and for
//! DEFOM-Stereo the width of the Depth Anything V2 inside, which tells ViT-S from ViT-L.

use std::path::Path;

use dgstereo_core::Result;
use dgstereo_prior::depth_anything::DepthAnythingV2Encoder;
use dgstereo_prior::depth_anything::checkpoint::encoder_from_keys;

/// A tensor's key and shape.
pub type KeyShape = (String, Vec<usize>);

/// Where DEFOM-Stereo keeps its Depth Anything V2 (`defomencoder.depth_anything.pretrained.*`,
/// `.depth_head.*`).
const DEFOM_DEPTH_ANYTHING: &str = "defomencoder.depth_anything.";

/// The modules every DEFOM-Stereo state dict holds.
const DEFOM_MODULES: [&str; 7] = [
    "defomencoder.depth_anything.pretrained.",
    "defomencoder.depth_anything.depth_head.",
    "fnet.",
    "cnet.",
    "update_block.",
    "scale_update_block.",
    "context_zqr_convs.",
];

/// The modules every IGEV-Stereo state dict holds (`spx` stands for `spx`, `spx_2`, `spx_4`,
/// `spx_gru`...).
const IGEV_MODULES: [&str; 8] =
    ["feature.", "cnet.", "corr_stem.", "cost_agg.", "classifier.", "spx", "update_block.", "context_zqr_convs."];

/// The tensors of a `.pth` checkpoint as its state dict: keys and shapes, sorted, with the
/// wrapper of a training checkpoint (`{'model': state_dict, 'optimizer': ...}`: only `model.*`
/// kept, the prefix removed) and DataParallel's `module.` prefix taken off.
pub fn state_dict_keys(path: &Path) -> Result<Vec<KeyShape>> {
    Ok(state_dict_of(dgstereo_model::official_keys::pth_keys(path)?))
}

/// `keys` (a checkpoint's tensors) as its state dict: see [`state_dict_keys`].
pub fn state_dict_of(keys: Vec<KeyShape>) -> Vec<KeyShape> {
    let wrapped = keys.iter().any(|(k, _)| k.starts_with("model."));
    let mut out: Vec<KeyShape> = keys
        .into_iter()
        .filter_map(|(key, shape)| {
            let key = if wrapped { key.strip_prefix("model.")?.to_string() } else { key };
            Some((key.strip_prefix("module.").map_or_else(|| key.clone(), str::to_string), shape))
        })
        .collect();
    out.sort();
    out
}

fn missing_modules(keys: &[KeyShape], modules: &[&str], what: &str) -> std::result::Result<(), String> {
    let missing: Vec<String> =
        modules.iter().filter(|m| !keys.iter().any(|(k, _)| k.starts_with(*m))).map(|m| format!("'{m}*'")).collect();
    if missing.is_empty() { Ok(()) } else { Err(format!("no {} keys: not {what} checkpoint", missing.join(", "))) }
}

/// The Depth Anything V2 encoder of the DEFOM-Stereo state dict `keys`, after checking that
/// every module of the model has keys and that the Depth Anything V2 inside is whole (its token
/// width names the size; its blocks and head widths must be that size's).
pub fn defom_encoder(keys: &[KeyShape]) -> std::result::Result<DepthAnythingV2Encoder, String> {
    missing_modules(keys, &DEFOM_MODULES, "a DEFOM-Stereo")?;
    let inner: Vec<KeyShape> =
        keys.iter().filter_map(|(k, s)| Some((k.strip_prefix(DEFOM_DEPTH_ANYTHING)?.to_string(), s.clone()))).collect();
    encoder_from_keys(&inner).map_err(|m| format!("its Depth Anything V2 ({DEFOM_DEPTH_ANYTHING}*): {m}"))
}

/// Checks that the state dict `keys` is IGEV-Stereo's: every module of the model has keys, and
/// the classifier of the geometry encoding volume is a 3D convolution to one channel.
pub fn check_igev(keys: &[KeyShape]) -> std::result::Result<(), String> {
    missing_modules(keys, &IGEV_MODULES, "an IGEV-Stereo")?;
    match keys.iter().find(|(k, _)| k == "classifier.weight") {
        Some((_, shape)) if shape.len() == 5 && shape[0] == 1 => Ok(()),
        Some((_, shape)) => Err(format!(
            "key 'classifier.weight' has shape {shape:?}: IGEV-Stereo's classifier is a 3D convolution to 1 channel"
        )),
        None => Err("missing key 'classifier.weight'".to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(list: &[(&str, &[usize])]) -> Vec<KeyShape> {
        list.iter().map(|(k, s)| (k.to_string(), s.to_vec())).collect()
    }

    #[test]
    fn a_training_wrapper_and_data_parallel_prefix_come_off() {
        let wrapped = keys(&[("model.module.fnet.conv1.weight", &[64]), ("optimizer.state.0.exp_avg", &[64])]);
        assert_eq!(state_dict_of(wrapped), keys(&[("fnet.conv1.weight", &[64])]));
        let plain = keys(&[("module.cnet.norm1.weight", &[64]), ("fnet.conv1.weight", &[64])]);
        assert_eq!(state_dict_of(plain), keys(&[("cnet.norm1.weight", &[64]), ("fnet.conv1.weight", &[64])]));
    }

    #[test]
    fn a_missing_module_is_named() {
        let e = check_igev(&keys(&[("feature.conv_stem.weight", &[32, 3, 3, 3])])).unwrap_err();
        assert!(e.contains("'cost_agg.*'") && e.contains("IGEV-Stereo"), "{e}");
        let e = defom_encoder(&keys(&[("fnet.conv1.weight", &[64, 3, 7, 7])])).unwrap_err();
        assert!(e.contains("'scale_update_block.*'") && e.contains("DEFOM-Stereo"), "{e}");
    }
}
