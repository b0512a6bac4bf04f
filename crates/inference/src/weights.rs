//! Finding the bundled assets and default weights, and loading a model from weights.
//!
//! Design decision: the default weights are looked up here, not by the callers, so every front
//! end (the command line, the Python package) falls back to the same bundled model; a fallback
//! worth telling the user about comes back as a note, never printed.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dgstereo_core::device::{cast_float_params, float_dtype};
use dgstereo_core::{Error, Result};
use dgstereo_model::checkpoint_config::{self, CheckpointConfig};
use dgstereo_model::{ModelConfig, StereoModel, checkpoint};

/// Folders that may hold the repository's `assets/`: beside the binary (installed layouts),
/// the checkout the binary was built from, and `DGSTEREO_ASSETS`.
fn asset_roots() -> Vec<PathBuf> {
    let mut roots = Vec::new();
    if let Some(p) = std::env::var_os("DGSTEREO_ASSETS") {
        roots.push(PathBuf::from(p));
    }
    if let Ok(exe) = std::env::current_exe() {
        for dir in exe.ancestors().skip(1).take(4) {
            roots.push(dir.join("assets"));
        }
    }
    roots.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets"));
    roots
}

/// A file under `assets/`, wherever the assets are.
pub fn asset(relative: &str) -> Result<PathBuf> {
    asset_in(&asset_roots(), relative)
}

/// A file under one of `roots`, or an error listing where it was looked for.
fn asset_in(roots: &[PathBuf], relative: &str) -> Result<PathBuf> {
    roots.iter().map(|r| r.join(relative)).find(|p| p.exists()).ok_or_else(|| {
        let looked: Vec<String> = roots.iter().map(|r| r.display().to_string()).collect();
        let reason = format!(
            "bundled asset not found (looked in {}; set DGSTEREO_ASSETS to a folder holding it)",
            looked.join(", ")
        );
        Error::io(relative, std::io::Error::new(std::io::ErrorKind::NotFound, reason))
    })
}

/// The bundled default without a prior (RAFT-Stereo, CPU-sized; `experiments/default/raft-stereo.toml`).
pub const DEFAULT_PLAIN: &str = "weights/raft-stereo-default.safetensors";
/// The bundled default of the paper's model, for runs with a prior
/// (`experiments/default/paper-simulated.toml`).
pub const DEFAULT_WITH_PRIOR: &str = "weights/paper-default.safetensors";

/// The weights used when none are given: the bundled default without a prior, or with
/// `with_prior` (the user gave a prior) the bundled paper model. Nothing stands in for them:
/// without the bundled file this is an error saying what is missing and how to give weights.
/// The second value is a note for the caller (none today).
pub fn default_weights(with_prior: bool) -> Result<(PathBuf, Option<String>)> {
    default_weights_in(&asset_roots(), with_prior)
}

/// As [`default_weights`], looking only in `DGSTEREO_ASSETS` and in `bundled` (a package's data
/// folder holding `weights/`), where one is given.
pub fn default_weights_at(bundled: Option<&Path>, with_prior: bool) -> Result<(PathBuf, Option<String>)> {
    match bundled {
        Some(dir) => {
            let mut roots: Vec<PathBuf> = std::env::var_os("DGSTEREO_ASSETS").map(PathBuf::from).into_iter().collect();
            roots.push(dir.to_path_buf());
            default_weights_in(&roots, with_prior)
        }
        None => default_weights(with_prior),
    }
}

fn default_weights_in(roots: &[PathBuf], with_prior: bool) -> Result<(PathBuf, Option<String>)> {
    let (file, what) = if with_prior {
        (DEFAULT_WITH_PRIOR, "the bundled paper model (for a run with a prior)")
    } else {
        (DEFAULT_PLAIN, "the bundled default weights")
    };
    let path = asset_in(roots, file).map_err(|e| {
        Error::config(
            "weights",
            format!(
                "{what} are missing: {e}. Give weights (an official RAFT-Stereo .pth, a dgstereo \
                 .safetensors, or a name such as raftstereo-sceneflow: `dgstereo weights list`), or \
                 install a build that carries assets/weights"
            ),
        )
    })?;
    Ok((path, None))
}

/// Loads weights (`.pth` official layout or our `.safetensors`) into a model of `config`.
/// A safetensors checkpoint that carries its own config uses it unless `config` is given; an
/// official `.pth` without `config` loads into the architecture its tensors show, with its
/// official preset's options, returned beside the model ([`checkpoint_config`]).
pub fn load_model(
    weights: &Path,
    config: Option<ModelConfig>,
    device: &Device,
) -> Result<(StereoModel, Option<CheckpointConfig>)> {
    let ext = weights.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let (network, config, detected) = match (config, ext.as_str()) {
        (None, "pth" | "pt") => {
            let (network, detected) = checkpoint_config::load_detected(weights, device)?;
            (network, detected.model.clone(), Some(detected))
        }
        (config, _) => {
            let config = match (config, ext.as_str()) {
                (Some(c), _) => c,
                (None, "safetensors") => match checkpoint::safetensors_metadata(weights, "model_config")? {
                    Some(json) => ModelConfig::from_checkpoint_json(&json).map_err(|e| {
                        Error::format(weights, format!("its model_config metadata does not parse: {e}"))
                    })?,
                    None => ModelConfig::default(),
                },
                (None, _) => ModelConfig::default(),
            };
            let network = config.init(device)?;
            let network = match ext.as_str() {
                "pth" | "pt" => checkpoint::load_pytorch(network, weights).map_err(|e| {
                    // Name what the file holds, when its tensors show it.
                    match checkpoint_config::detect(weights, device) {
                        Ok(d) => e.context(format!(
                            "the checkpoint's tensors show: {}; loading it as configured",
                            checkpoint_config::summary(&d.model)
                        )),
                        Err(_) => e,
                    }
                })?,
                "safetensors" => checkpoint::load_safetensors(network, weights)?,
                _ => {
                    let reason =
                        format!("{}: unknown weights format (expected .pth or .safetensors)", weights.display());
                    return Err(Error::config("weights", reason));
                }
            };
            (network, config, None)
        }
    };
    // The stores keep the file's dtype: bring the weights to the device's (see [`crate::EngineConfig::precision`]).
    let network = cast_float_params(network, float_dtype(device));
    Ok((StereoModel::new(network, config, device.clone()), detected))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_default_weights_are_an_error_naming_them_never_a_stand_in() {
        let empty = tempfile::tempdir().unwrap();
        let roots = [empty.path().to_path_buf()];
        for (with_prior, file) in [(false, DEFAULT_PLAIN), (true, DEFAULT_WITH_PRIOR)] {
            let e = default_weights_in(&roots, with_prior).unwrap_err().to_string();
            assert!(e.contains(file) && e.contains("DGSTEREO_ASSETS") && e.contains("weights"), "{e}");
            assert!(e.contains(&empty.path().display().to_string()), "{e}");
        }
        let weights = empty.path().join("weights");
        std::fs::create_dir_all(&weights).unwrap();
        std::fs::write(weights.join("raft-stereo-default.safetensors"), b"x").unwrap();
        let (found, note) = default_weights_in(&roots, false).unwrap();
        assert_eq!((found, note), (weights.join("raft-stereo-default.safetensors"), None));
    }
}
