//! The state-dict keys of official IGEV-Stereo checkpoints that differ from our module paths.
//!
//! They apply to a model with the geometry encoding volume only (their names clash with
//! RAFT-Stereo's): the reference names its GRUs by their level's stride (`gru04` at 1/4), ours
//! by RAFT-Stereo's (`gru08` at 1/4); the volume's modules sit at the reference's top level
//! (`conv`, `desc`, `corr_stem`, `corr_feature_att`, `cost_agg`, `classifier`), ours under
//! `geometry`, the superpixel heads (`spx*`) under `superpixel` and the feature pyramid and
//! stems under `encoder`; the feature gates' `feat_att.0`/`feat_att.1` and the mask feature's
//! `mask_feat_4.0` index a `Sequential`, ours are named fields. The encoder's and the superpixel
//! heads' own renames are their crates' ([`IGEV_ENCODER_RENAMES`], [`SUPERPIXEL_RENAMES`]);
//! [`from_official`] and [`to_official`] put every list in its order.

use dgstereo_encoder::official_keys::{IGEV_ENCODER_INVERSE_RENAMES, IGEV_ENCODER_RENAMES};
use dgstereo_updater::superpixel::{SUPERPIXEL_INVERSE_RENAMES, SUPERPIXEL_RENAMES};

/// Renames from the official keys (after the common renames) to our module paths, applied in
/// order (each GRU moves to a name the next rename no longer matches).
pub const FROM_OFFICIAL: &[(&str, &str)] = &[
    (r"^update_block\.gru16\.", "update_block.gru32."),
    (r"^update_block\.gru08\.", "update_block.gru16."),
    (r"^update_block\.gru04\.", "update_block.gru08."),
    (r"^update_block\.mask_feat_4\.0\.", "update_block.mask_feat_4.conv."),
    (r"^(conv|desc|corr_stem|corr_feature_att|cost_agg|classifier)\.", "geometry.$1."),
    (r"\.feat_att\.0\.", ".reduce."),
    (r"\.feat_att\.1\.", ".expand."),
    (r"^(spx|spx_2|spx_4|spx_2_gru|spx_gru)\.", "superpixel.$1."),
    (r"^(feature|stem_2|stem_4)\.", "encoder.$1."),
];

/// The inverse of [`FROM_OFFICIAL`], from our module paths (after the common inverse renames,
/// which drop enum variants and `encoder.`) to the official keys, applied in order.
pub const TO_OFFICIAL: &[(&str, &str)] = &[
    (r"^superpixel\.", ""),
    (r"^update_block\.gru08\.", "update_block.gru04."),
    (r"^update_block\.gru16\.", "update_block.gru08."),
    (r"^update_block\.gru32\.", "update_block.gru16."),
    (r"^update_block\.mask_feat_4\.conv\.", "update_block.mask_feat_4.0."),
    (r"^geometry\.", ""),
    (r"(corr_feature_att|feature_att_\w+)\.reduce\.", "$1.feat_att.0."),
    (r"(corr_feature_att|feature_att_\w+)\.expand\.", "$1.feat_att.1."),
];

/// Every rename from an official IGEV-Stereo key to our module path, in order: the `module.`
/// prefix, the encoder's and the superpixel heads' renames, [`FROM_OFFICIAL`], then `common`
/// (RAFT-Stereo's, which then only move `cnet` under `encoder`).
pub fn from_official(common: &[(&'static str, &'static str)]) -> Vec<(&'static str, &'static str)> {
    let mut renames = vec![(r"^module\.", "")];
    renames.extend_from_slice(IGEV_ENCODER_RENAMES);
    renames.extend_from_slice(SUPERPIXEL_RENAMES);
    renames.extend_from_slice(FROM_OFFICIAL);
    renames.extend_from_slice(common);
    renames
}

/// Every rename from one of our module paths, after RAFT-Stereo's inverse renames, to the
/// official IGEV-Stereo key, in order: [`TO_OFFICIAL`], then the superpixel heads' and the
/// encoder's inverse renames.
pub fn to_official() -> Vec<(&'static str, &'static str)> {
    let mut renames = TO_OFFICIAL.to_vec();
    renames.extend_from_slice(SUPERPIXEL_INVERSE_RENAMES);
    renames.extend_from_slice(IGEV_ENCODER_INVERSE_RENAMES);
    renames
}

#[cfg(test)]
mod tests {
    use burn::store::KeyRemapper;

    use super::*;

    fn apply(renames: &[(&str, &str)], key: &str) -> String {
        let remapper = KeyRemapper::from_patterns(renames.to_vec()).unwrap();
        remapper.patterns.iter().fold(key.to_string(), |k, (p, r)| p.replace_all(&k, r.as_str()).into_owned())
    }

    /// Every renamed key comes back from our path to the official one, the GRUs each to its
    /// own level.
    #[test]
    fn the_renames_are_each_others_inverse() {
        let cases = [
            ("update_block.gru04.convz.weight", "update_block.gru08.convz.weight"),
            ("update_block.gru08.convq.bias", "update_block.gru16.convq.bias"),
            ("update_block.gru16.convr.weight", "update_block.gru32.convr.weight"),
            ("update_block.mask_feat_4.0.weight", "update_block.mask_feat_4.conv.weight"),
            ("corr_feature_att.feat_att.0.bn.running_var", "geometry.corr_feature_att.reduce.bn.running_var"),
            ("cost_agg.feature_att_up_16.feat_att.1.bias", "geometry.cost_agg.feature_att_up_16.expand.bias"),
            ("cost_agg.conv1.0.conv.weight", "geometry.cost_agg.conv1.0.conv.weight"),
            ("conv.conv.weight", "geometry.conv.conv.weight"),
            ("update_block.encoder.convd1.weight", "update_block.encoder.convd1.weight"),
        ];
        for (official, ours) in cases {
            assert_eq!(apply(FROM_OFFICIAL, official), ours, "{official}");
            assert_eq!(apply(TO_OFFICIAL, ours), official, "{ours}");
        }
        // The whole lists, with the encoder's and the superpixel heads': a context head moves a
        // stride, a stem and a superpixel head leave their `Sequential` indices.
        let whole = [
            ("module.cnet.outputs04.0.0.conv1.weight", "encoder.cnet.outputs08.0.block.conv1.weight"),
            ("stem_2.1.weight", "encoder.stem_2.conv.weight"),
            ("spx_gru.0.bias", "superpixel.spx_gru.bias"),
            ("spx_4.0.conv.weight", "superpixel.spx_4.block.conv.weight"),
            ("feature.conv_stem.weight", "encoder.feature.conv_stem.weight"),
        ];
        let common = [(r"^(fnet|cnet|conv2)\.", "encoder.$1.")];
        for (official, ours) in whole {
            assert_eq!(apply(&from_official(&common), official), ours, "{official}");
        }
    }
}
