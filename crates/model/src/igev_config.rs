//! The IGEV-Stereo configuration of a checkpoint, read from its tensors.
//!
//! An IGEV-Stereo state dict (`sceneflow.pth` and the fine-tuned ones) is recognised by its
//! MobileNetV2 feature pyramid (`feature.conv_stem.weight`) and its geometry volume's
//! aggregation (`cost_agg.*`). Its tensors show:
//! - the hidden widths, from the GRUs (`update_block.gru16/gru08/gru04`, coarsest first);
//! - the GRU levels, from the count of `context_zqr_convs.{i}`;
//! - the correlation groups, from `corr_stem.conv.weight`'s channels;
//! - `levels · (2·radius + 1) · (groups + 1)`, the motion encoder's input channels, split as
//!   RAFT-Stereo's count is (the caller's rule, `checkpoint_config::correlation_split`) once
//!   divided by `groups + 1`;
//! - the context encoder's trunk widths and norm, as RAFT-Stereo's.
//!
//! The rest is IGEV-Stereo's architecture: the disparity motion, superpixel upsampling, the
//! soft-argmin start, `n_downsample` 2; `max_disp` (192) is the official demo's and evaluation's
//! argument, which no tensor shows (the volume's depth is the input's, not a weight's).

use std::collections::BTreeMap;

use dgstereo_costvolume::GeometryVolume;
use dgstereo_encoder::{EncoderLayout, NormKind};
use dgstereo_updater::{MotionKind, UpsamplingKind};

use crate::key_shapes::{dim, gru_levels};
use crate::{InitialDisparity, ModelConfig};

/// Whether a state dict is IGEV-Stereo's: the MobileNetV2 pyramid and the geometry volume's
/// aggregation.
pub fn is_igev(keys: &BTreeMap<&str, &[usize]>) -> bool {
    keys.contains_key("feature.conv_stem.weight") || keys.keys().any(|k| k.starts_with("cost_agg."))
}

/// The IGEV-Stereo architecture `keys` show, or the problems with them; `split` divides a
/// correlation channel count into `(levels, radius)`.
pub fn architecture(
    keys: &BTreeMap<&str, &[usize]>,
    split: impl Fn(usize) -> Option<(usize, usize)>,
) -> Result<ModelConfig, Vec<String>> {
    let mut problems = Vec::new();
    let mut config = ModelConfig::default();
    config.encoder.layout = EncoderLayout::MobilenetPyramid;
    config.encoder.trunk_dims = [
        dim(keys, "cnet.conv1.weight", 0, &mut problems),
        dim(keys, "cnet.layer2.0.conv1.weight", 0, &mut problems),
        dim(keys, "cnet.layer3.0.conv1.weight", 0, &mut problems),
    ];
    config.encoder.context_norm = if keys.contains_key("cnet.norm1.running_mean") {
        NormKind::Batch
    } else if keys.contains_key("cnet.norm1.weight") {
        NormKind::Group
    } else {
        NormKind::Instance
    };
    config.updater.hidden_dims = [
        dim(keys, "update_block.gru16.convz.weight", 0, &mut problems),
        dim(keys, "update_block.gru08.convz.weight", 0, &mut problems),
        dim(keys, "update_block.gru04.convz.weight", 0, &mut problems),
    ];
    config.updater.n_gru_layers = gru_levels(keys, &mut problems);
    config.updater.n_downsample = 2;
    config.updater.motion = MotionKind::Disparity;
    config.updater.upsampling = UpsamplingKind::Superpixel;
    let groups = dim(keys, "corr_stem.conv.weight", 0, &mut problems);
    let corr = dim(keys, "update_block.encoder.convc1.weight", 1, &mut problems);
    if groups > 0 && corr > 0 {
        match corr.is_multiple_of(groups + 1).then(|| split(corr / (groups + 1))).flatten() {
            Some((l, r)) => (config.correlation.levels, config.correlation.radius) = (l, r),
            None => problems.push(format!(
                "'update_block.encoder.convc1.weight' has {corr} input channels: not levels·(2·radius + 1)·{} for \
                 {groups} correlation groups",
                groups + 1
            )),
        }
    }
    config.correlation.geometry = Some(GeometryVolume { groups, ..GeometryVolume::default() });
    config.initial_disparity = InitialDisparity::SoftArgmin {};
    if problems.is_empty() { Ok(config) } else { Err(problems) }
}

/// IGEV-Stereo's options on one line (`IGEV-Stereo: geometry volume max_disp 192, 8 groups,
/// ...`), `None` for a model without the geometry volume.
pub fn summary(config: &ModelConfig) -> Option<String> {
    let geometry = config.correlation.geometry.as_ref()?;
    Some(format!(
        "IGEV-Stereo: geometry volume max_disp {}, {} groups, initial disparity {}, {} upsampling",
        geometry.max_disp,
        geometry.groups,
        config.initial_disparity.kind(),
        serde_json::to_value(config.updater.upsampling)
            .ok()
            .and_then(|v| v.as_str().map(String::from))
            .unwrap_or_default(),
    ))
}
