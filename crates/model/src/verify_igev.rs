//! Conformance of IGEV-Stereo with the official code, on seeded weights.
//!
//! `../shared/golden/igev_stereo_seeded.activations.safetensors` holds what the official
//! IGEV-Stereo (gangweiX/IGEV, `IGEV-Stereo/core`, float32, CPU) computed on a 96x128 pair with
//! seeded weights and `demo_imgs.py`'s arguments, 4 iterations, and in its metadata the key and
//! shape of every weight. [`verify_igev`] rebuilds the weights from that metadata
//! ([`crate::seeded`]), reads the configuration from their keys and shapes alone
//! ([`crate::checkpoint_config`]), loads them through the official-checkpoint loader, runs the
//! file's iterations on its inputs and compares every recorded tensor (the official module
//! outputs, named `MODULE.callK.I.J`) with ours: both views' feature pyramids and image stems,
//! the geometry encoding volume's path (`corr_stem`, `corr_feature_att`, `cost_agg`,
//! `classifier`), the initial superpixel weights' path, the context encoder, every update
//! block's states, mask feature and update, every iteration's superpixel logits, and the
//! upsampled initial and iterated disparities. Disparities must agree within
//! [`DISPARITY_TOLERANCE`] pixels, the rest within [`crate::verify::FEATURE_TOLERANCE`] of the
//! tensor's largest magnitude.

use std::path::Path;

use burn::tensor::Device;
use dgstereo_core::{Error, Result};

use crate::checkpoint_config;
use crate::seeded_verify::{SeededModel, load_seeded, traced_pass};
use crate::verify::VerifyReport;
use crate::verify_defom::compare_trace;

pub use crate::verify_defom::DISPARITY_TOLERANCE;

/// The name our trace gives the tensor a golden key records, `None` for keys that are no output
/// (`input.*`) or that this implementation does not know.
pub fn traced_name(key: &str) -> Option<String> {
    let parts: Vec<&str> = key.split('.').collect();
    let call = |p: &str| p.strip_prefix("call").and_then(|c| c.parse::<usize>().ok());
    let side = |p: &str| match call(p)? {
        0 => Some("left"),
        1 => Some("right"),
        _ => None,
    };
    match parts.as_slice() {
        ["feature", c, level] => Some(format!("feature.{}.{level}", side(c)?)),
        [stem @ ("stem_2" | "stem_4"), c] => Some(format!("{stem}.{}", side(c)?)),
        [module @ ("corr_stem" | "corr_feature_att" | "cost_agg" | "classifier"), "call0"] => {
            Some(format!("geometry.{module}"))
        }
        [module @ ("spx_4" | "spx_2" | "spx"), "call0"] => Some(format!("superpixel.{module}")),
        ["cnet", "call0", level, head] => Some(format!("cnet.{level}.{head}")),
        ["update_block", c, rest @ ..] => {
            let k = call(c)?;
            match rest {
                ["0", level] => Some(format!("iter.{k}.hidden.{level}")),
                ["1"] => Some(format!("iter.{k}.up_mask")),
                ["2"] => Some(format!("iter.{k}.prediction")),
                _ => None,
            }
        }
        ["spx_gru", c] => Some(format!("iter.{}.spx_gru", call(c)?)),
        ["disparity", "init"] => Some("initial_disparity_up".into()),
        ["disparity", iteration] => {
            let k: usize = iteration.strip_prefix("iter")?.parse().ok()?;
            Some(format!("iter.{k}.disparity_up"))
        }
        _ => None,
    }
}

/// Runs IGEV-Stereo with the seeded weights of `reference` (configuration from their keys and
/// shapes, loaded as an official checkpoint) on its inputs, for its `iters`, and compares every
/// tensor it recorded.
///
/// # Errors
/// [`Error::Io`], [`Error::Format`] when the file cannot be read or lacks what a seeded golden
/// holds; [`Error::Checkpoint`] when its keys match no configuration or do not load;
/// [`Error::Shape`] when a tensor we produce has another shape than the reference's.
pub fn verify_igev(reference: &Path, device: &Device) -> Result<VerifyReport> {
    let SeededModel { config, model, iters, .. } = load_seeded(reference, device)?;
    if config.preset != checkpoint_config::OfficialPreset::Igev {
        let message = format!("the keys are not an IGEV-Stereo state dict (they show {config})");
        return Err(Error::Checkpoint { path: reference.into(), message });
    }
    let (refs, trace) = traced_pass(&model, reference, iters, device)?;

    let last = format!("disparity.iter{}", iters.saturating_sub(1));
    let (lines, unmatched, final_flow_error) = compare_trace(&refs, &trace, traced_name, &last)?;
    let configuration = format!("{config}; seeded weights, {iters} iterations");
    Ok(VerifyReport { lines, final_flow_error, unmatched, configuration })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_names_map_to_traced_ones() {
        let cases = [
            ("feature.call0.0", "feature.left.0"),
            ("feature.call1.3", "feature.right.3"),
            ("stem_2.call1", "stem_2.right"),
            ("stem_4.call0", "stem_4.left"),
            ("corr_stem.call0", "geometry.corr_stem"),
            ("classifier.call0", "geometry.classifier"),
            ("spx_2.call0", "superpixel.spx_2"),
            ("cnet.call0.2.1", "cnet.2.1"),
            ("update_block.call3.0.1", "iter.3.hidden.1"),
            ("update_block.call0.1", "iter.0.up_mask"),
            ("update_block.call2.2", "iter.2.prediction"),
            ("spx_gru.call1", "iter.1.spx_gru"),
            ("disparity.init", "initial_disparity_up"),
            ("disparity.iter3", "iter.3.disparity_up"),
        ];
        for (key, name) in cases {
            assert_eq!(traced_name(key).as_deref(), Some(name), "{key}");
        }
        for key in ["input.left", "feature.call2.0", "update_block.callx.1", "cost_agg.call1", "other.call0"] {
            assert_eq!(traced_name(key), None, "{key}");
        }
    }
}
