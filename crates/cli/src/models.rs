//! Finding the bundled assets and default weights, and loading a model from weights.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use burn::tensor::Device;
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
pub fn asset(relative: &str) -> anyhow::Result<PathBuf> {
    asset_roots().into_iter().map(|r| r.join(relative)).find(|p| p.exists()).with_context(|| {
        format!("bundled asset '{relative}' not found (set DGSTEREO_ASSETS to the repository's assets/ folder)")
    })
}

/// The weights used when none are given: the project's default model if it is bundled, else
/// the reference checkpoint of `../shared/golden` (random weights: a placeholder until trained
/// defaults exist).
pub fn default_weights() -> anyhow::Result<PathBuf> {
    if let Ok(p) = asset("weights/raft-stereo-default.safetensors") {
        return Ok(p);
    }
    if let Some(shared) = dgstereo_core::shared::shared_dir() {
        let p = shared.join("golden/raft_stereo_random.pth");
        if p.is_file() {
            eprintln!(
                "note: no trained default weights are bundled yet; using the reference checkpoint {} (random weights)",
                p.display()
            );
            return Ok(p);
        }
    }
    bail!("no default weights found: pass --weights FILE (an official RAFT-Stereo .pth or a dgstereo .safetensors)")
}

/// Loads weights (`.pth` official layout or our `.safetensors`) into a model of `config`.
/// A safetensors checkpoint that carries its own config uses it unless `config` is given.
pub fn load_model(weights: &Path, config: Option<ModelConfig>, device: &Device) -> anyhow::Result<StereoModel> {
    let ext = weights.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let config = match (config, ext.as_str()) {
        (Some(c), _) => c,
        (None, "safetensors") => match checkpoint::safetensors_metadata(weights, "model_config")? {
            Some(json) => serde_json::from_str(&json)
                .with_context(|| format!("{}: its model_config metadata does not parse", weights.display()))?,
            None => ModelConfig::default(),
        },
        (None, _) => ModelConfig::default(),
    };
    let network = config.init(device)?;
    let network = match ext.as_str() {
        "pth" | "pt" => checkpoint::load_pytorch(network, weights)?,
        "safetensors" => checkpoint::load_safetensors(network, weights)?,
        _ => bail!("{}: unknown weights format (expected .pth or .safetensors)", weights.display()),
    };
    Ok(StereoModel::new(network, config, device.clone()))
}
