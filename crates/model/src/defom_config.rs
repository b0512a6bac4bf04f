//! The DEFOM-Stereo part of a checkpoint's configuration, read from its tensors.
//!
//! A DEFOM-Stereo state dict (`defomstereo_*.pth`) is RAFT-Stereo's, which
//! [`crate::checkpoint_config`] reads (levels and radius from the motion encoder's input, hidden
//! widths, context norm, `n_downsample`), plus:
//! - the ViT size of its Depth Anything V2, from `defomencoder.depth_anything.*` as the prior
//!   crate reads a Depth Anything V2 checkpoint (token width, blocks, head widths);
//! - the encoders' monocular feature blocks (`fnet.convd`, `cnet.conv08`), whose input width
//!   must be that ViT's feature width;
//! - the disparity motion input (`update_block.encoder.convd1`, one channel);
//! - the scale update block (`scale_update_block.*`) and its lookup's channel count, `scales ·
//!   (2·radius + 1)`.
//!
//! What the tensors cannot show comes from the official evaluation's arguments
//! (`evaluate_stereo.py`, `demo.py`): the scales 0.125..2 with radius 2 (the only split of the
//! channel count that is accepted: the scales themselves are not in the tensors), `idepth_scale`
//! 0.5 and the update clip; 32 iterations, of which 8 scale iterations.

use std::collections::BTreeMap;

use dgstereo_costvolume::ScaleLookup;
use dgstereo_encoder::DepthFeatureInput;
use dgstereo_prior::MonocularConfig;
use dgstereo_prior::depth_anything::checkpoint::encoder_from_keys;
use dgstereo_updater::{MotionKind, ScaleUpdateConfig};

use crate::{InitialDisparity, ModelConfig};

/// The key prefix of DEFOM-Stereo's Depth Anything V2.
pub const MONOCULAR_PREFIX: &str = "defomencoder.depth_anything.";

/// Scale iterations of the official evaluation (`--scale_iters 8`).
pub const OFFICIAL_SCALE_ITERS: usize = 8;

/// Whether a state dict is DEFOM-Stereo's (it embeds Depth Anything V2).
pub fn is_defom(keys: &BTreeMap<&str, &[usize]>) -> bool {
    keys.keys().any(|k| k.starts_with(MONOCULAR_PREFIX))
}

/// Completes `config` (RAFT-Stereo's part already read) with DEFOM-Stereo's variants from
/// `keys`; what disagrees is added to `problems`, naming the key.
pub fn complete(config: &mut ModelConfig, keys: &BTreeMap<&str, &[usize]>, problems: &mut Vec<String>) {
    let monocular: Vec<(String, Vec<usize>)> = keys
        .iter()
        .filter_map(|(k, s)| k.strip_prefix(MONOCULAR_PREFIX).map(|k| (k.to_string(), s.to_vec())))
        .collect();
    let encoder = match encoder_from_keys(&monocular) {
        Ok(encoder) => encoder,
        Err(message) => {
            problems.push(format!("Depth Anything V2 under '{MONOCULAR_PREFIX}': {message}"));
            return;
        }
    };
    config.monocular = MonocularConfig::DepthAnythingV2 { encoder };
    config.initial_disparity = InitialDisparity::scaled_inverse_depth();
    let width = encoder.features();
    for key in ["fnet.convd.conv.weight", "cnet.conv08.conv.weight"] {
        match keys.get(key) {
            Some(s) if s.get(1) == Some(&width) => {}
            Some(s) => {
                problems.push(format!("'{key}' has shape {s:?}: the {encoder} network's features are {width} wide"))
            }
            None => problems.push(format!("missing key '{key}' (the encoders' monocular feature block)")),
        }
    }
    config.encoder.depth_features = DepthFeatureInput::Added;
    if keys.contains_key("update_block.encoder.convd1.weight") {
        config.updater.motion = MotionKind::Disparity;
    }
    config.updater.delta_clip = true;
    if let Some(shape) = keys.get("scale_update_block.encoder.convc1.weight") {
        let lookup = ScaleLookup::default();
        match shape.get(1) {
            Some(&c) if c == lookup.channels() => {
                config.correlation.scale_lookup = Some(lookup);
                config.updater.scale_update = Some(ScaleUpdateConfig { iters: OFFICIAL_SCALE_ITERS });
            }
            _ => problems.push(format!(
                "'scale_update_block.encoder.convc1.weight' has shape {shape:?}: the scale lookup of the official \
                 scales (0.125..2, radius 2) gives {} channels, and other scales cannot be read from the tensors",
                lookup.channels()
            )),
        }
    }
}

/// DEFOM-Stereo's options on one line (`DEFOM-Stereo: Depth Anything V2 vits, ...`), `None` for
/// a model without a monocular network.
pub fn summary(config: &ModelConfig) -> Option<String> {
    let MonocularConfig::DepthAnythingV2 { encoder } = config.monocular else { return None };
    let scale = match (&config.updater.scale_update, &config.correlation.scale_lookup) {
        (Some(update), Some(lookup)) => {
            format!(
                "scale update {} iterations ({} scales, radius {})",
                update.iters,
                lookup.scales.len(),
                lookup.radius
            )
        }
        _ => "no scale update".into(),
    };
    let init = match config.initial_disparity {
        InitialDisparity::ScaledInverseDepth { scale } => format!("initial disparity {scale} x inverse depth"),
        InitialDisparity::Zero {} => "initial disparity 0".into(),
        InitialDisparity::SoftArgmin {} => "initial disparity soft-argmin".into(),
    };
    Some(format!("DEFOM-Stereo: Depth Anything V2 {encoder}, {scale}, {init}"))
}
