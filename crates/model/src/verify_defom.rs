//! Conformance of DEFOM-Stereo with the official code, on seeded weights.
//!
//! `../shared/golden/defom_stereo_vits_seeded.activations.safetensors` holds what the official
//! DEFOM-Stereo (Insta360-Research-Team/DEFOM-Stereo, float32, CPU) computed on a 96x128 pair
//! with ViT-S and seeded weights, 6 iterations of which 3 scale iterations, and in its metadata
//! the key and shape of every weight. [`verify_defom`] rebuilds the weights from that metadata
//! ([`crate::seeded`]), reads the configuration from their keys and shapes alone
//! ([`crate::checkpoint_config`]), loads them through the official-checkpoint loader
//! ([`crate::checkpoint::load_state_dict`]), runs the file's iterations on its inputs and
//! compares every recorded tensor (the official module outputs, named `MODULE.callK.I.J`) with
//! ours: the monocular network's features and inverse depth, the initial disparity, the context
//! and feature encoders, every scale and normal update block's states, mask and prediction, and
//! every iteration's upsampled disparity. Disparities must agree within
//! [`DISPARITY_TOLERANCE`] pixels, the rest within [`FEATURE_TOLERANCE`] of the tensor's largest
//! magnitude.

use std::path::Path;

use burn::tensor::Device;
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, Result};

use crate::Trace;
use crate::seeded_verify::{SeededModel, load_seeded, metadata_count, traced_pass};
use crate::verify::{FEATURE_TOLERANCE, ReferenceTensors, VerifyLine, VerifyReport};

/// Tolerance on disparities (absolute, pixels).
pub const DISPARITY_TOLERANCE: f32 = 1e-4;

/// The name our trace gives the tensor a golden key records, `None` for keys that are no output
/// (`input.*`, the kept buffers `state.*`) or that this implementation does not know.
/// `scale_iters` numbers the normal block's calls after the scale block's.
pub fn traced_name(key: &str, scale_iters: usize) -> Option<String> {
    let parts: Vec<&str> = key.split('.').collect();
    let call = |p: &str| p.strip_prefix("call").and_then(|c| c.parse::<usize>().ok());
    let monocular = |rest: &[&str], last: &str| match rest {
        ["0", level] => Some(format!("monocular.context.{level}")),
        ["1"] => Some("monocular.left".into()),
        ["2"] => Some("monocular.right".into()),
        ["3"] => Some(last.to_string()),
        _ => None,
    };
    let block = |k: usize, rest: &[&str]| match rest {
        ["0", level] => Some(format!("iter.{k}.hidden.{level}")),
        ["1"] => Some(format!("iter.{k}.up_mask")),
        ["2"] => Some(format!("iter.{k}.prediction")),
        _ => None,
    };
    match parts.as_slice() {
        ["defomencoder", "depth_anything", "call0", rest @ ..] => monocular(rest, "monocular.inverse_depth"),
        ["defomencoder", "call0", rest @ ..] => monocular(rest, "initial_disparity"),
        ["cnet", "call0", level, head] => Some(format!("cnet.{level}.{head}")),
        ["fnet", "call0", "0"] => Some("fnet.left".into()),
        ["fnet", "call0", "1"] => Some("fnet.right".into()),
        ["scale_update_block", c, rest @ ..] => block(call(c)?, rest),
        ["update_block", c, rest @ ..] => block(call(c)? + scale_iters, rest),
        ["disparity", iteration] => {
            let k: usize = iteration.strip_prefix("iter")?.parse().ok()?;
            Some(format!("iter.{k}.disparity_up"))
        }
        _ => None,
    }
}

/// Whether a golden key is a disparity, compared in pixels.
fn is_disparity(key: &str) -> bool {
    key.starts_with("disparity.")
}

/// Runs DEFOM-Stereo with the seeded weights of `reference` (configuration from their keys and
/// shapes, loaded as an official checkpoint) on its inputs, for its `iters` and `scale_iters`,
/// and compares every tensor it recorded.
///
/// # Errors
/// [`Error::Io`], [`Error::Format`] when the file cannot be read or lacks what a seeded golden
/// holds; [`Error::Checkpoint`] when its keys match no configuration or do not load;
/// [`Error::Shape`] when a tensor we produce has another shape than the reference's.
pub fn verify_defom(reference: &Path, device: &Device) -> Result<VerifyReport> {
    let SeededModel { config, mut model, metadata, iters } = load_seeded(reference, device)?;
    let scale_iters = metadata_count(&metadata, "scale_iters", reference)?;
    model.scale_iters = scale_iters;
    let (refs, trace) = traced_pass(&model, reference, iters, device)?;

    let last = format!("disparity.iter{}", iters.saturating_sub(1));
    let (lines, unmatched, final_flow_error) = compare_trace(&refs, &trace, |k| traced_name(k, scale_iters), &last)?;
    let configuration = format!("{config}; seeded weights, {iters} iterations of which {scale_iters} scale iterations");
    Ok(VerifyReport { lines, final_flow_error, unmatched, configuration })
}

/// Compares every output the reference `refs` holds (not `input.*` nor `state.*`) with the
/// traced tensor `name_of` names: disparities (`disparity.*`) within [`DISPARITY_TOLERANCE`]
/// pixels, the rest within [`FEATURE_TOLERANCE`] of the reference's largest magnitude. A 5-D
/// reference (a cost volume `[N, C, D, H, W]`) compares with the trace's `[N, C·D, H, W]`.
/// Returns the lines, the keys without a traced tensor and the error of `last`.
///
/// # Errors
/// [`Error::Shape`] when a traced tensor's shape is not the reference's.
pub(crate) fn compare_trace(
    refs: &ReferenceTensors,
    trace: &Trace,
    name_of: impl Fn(&str) -> Option<String>,
    last: &str,
) -> Result<(Vec<VerifyLine>, Vec<String>, f32)> {
    let mut lines = Vec::new();
    let mut unmatched = Vec::new();
    let mut final_flow_error = f32::NAN;
    for (key, (shape, expected)) in refs {
        if key.starts_with("input.") || key.starts_with("state.") {
            continue;
        }
        let Some(actual) = name_of(key).and_then(|name| trace.get(&name)) else {
            unmatched.push(key.clone());
            continue;
        };
        let dims = actual.dims().to_vec();
        let flattened = match shape.as_slice() {
            [n, c, d, h, w] => dims == [*n, c * d, *h, *w],
            _ => false,
        };
        if dims != *shape && !flattened {
            return Err(Error::Shape(format!("{key}: produced {dims:?}, reference {shape:?}")));
        }
        let actual = to_vec(actual.clone());
        let max_abs_error = actual.iter().zip(expected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let scale = expected.iter().map(|v| v.abs()).fold(0.0f32, f32::max).max(1e-6);
        let relative_error = max_abs_error / scale;
        let passed = match is_disparity(key) {
            true => max_abs_error <= DISPARITY_TOLERANCE,
            false => relative_error <= FEATURE_TOLERANCE,
        };
        if key == last {
            final_flow_error = max_abs_error;
        }
        lines.push(VerifyLine {
            key: key.clone(),
            shape: shape.clone(),
            max_abs_error,
            relative_error,
            passed: passed && max_abs_error.is_finite(),
        });
    }
    Ok((lines, unmatched, final_flow_error))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_names_map_to_traced_ones() {
        let cases = [
            ("defomencoder.depth_anything.call0.0.2", "monocular.context.2"),
            ("defomencoder.depth_anything.call0.3", "monocular.inverse_depth"),
            ("defomencoder.call0.1", "monocular.left"),
            ("defomencoder.call0.3", "initial_disparity"),
            ("cnet.call0.2.1", "cnet.2.1"),
            ("fnet.call0.1", "fnet.right"),
            ("scale_update_block.call2.0.1", "iter.2.hidden.1"),
            ("update_block.call0.2", "iter.3.prediction"),
            ("update_block.call2.1", "iter.5.up_mask"),
            ("disparity.iter5", "iter.5.disparity_up"),
        ];
        for (key, name) in cases {
            assert_eq!(traced_name(key, 3).as_deref(), Some(name), "{key}");
        }
        for key in ["input.left", "update_block.callx.1", "fnet.call0.2", "disparity.final", "other.call0"] {
            assert_eq!(traced_name(key, 3), None, "{key}");
        }
    }
}
