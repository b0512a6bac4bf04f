//! The state-dict keys of official IGEV-Stereo checkpoints that differ from our module paths.
//!
//! They apply to a model with the geometry encoding volume only (their names clash with
//! RAFT-Stereo's): the reference names its GRUs by their level's stride (`gru04` at 1/4), ours
//! by RAFT-Stereo's (`gru08` at 1/4); the volume's modules sit at the reference's top level
//! (`conv`, `desc`, `corr_stem`, `corr_feature_att`, `cost_agg`, `classifier`), ours under
//! `geometry`; the feature gates' `feat_att.0`/`feat_att.1` and the mask feature's
//! `mask_feat_4.0` index a `Sequential`, ours are named fields.

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
];

/// The inverse of [`FROM_OFFICIAL`], from our module paths to the official keys, applied in
/// order before the common inverse renames.
pub const TO_OFFICIAL: &[(&str, &str)] = &[
    (r"^update_block\.gru08\.", "update_block.gru04."),
    (r"^update_block\.gru16\.", "update_block.gru08."),
    (r"^update_block\.gru32\.", "update_block.gru16."),
    (r"^update_block\.mask_feat_4\.conv\.", "update_block.mask_feat_4.0."),
    (r"^geometry\.", ""),
    (r"(corr_feature_att|feature_att_\w+)\.reduce\.", "$1.feat_att.0."),
    (r"(corr_feature_att|feature_att_\w+)\.expand\.", "$1.feat_att.1."),
];

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
    }
}
