//! Where the official checkpoints' keys and our module paths differ: one table per model family,
//! read in both directions, and the one rule for the keys the loader ignores.
//!
//! Our field names follow the official state dicts, so a key is a path as it stands except where
//! a PyTorch `Sequential` index has no Rust field name (`outputs08.0.1` is `outputs08.0.conv`,
//! `mask.2` is `mask.conv2`, `downsample.0` is `downsample`, Depth Anything's `resize_layers.0` is
//! `upsample_4x`, ...), where a module sits at another place in our tree (the encoder layout's
//! modules under `encoder`, DEFOM-Stereo's `defomencoder.depth_anything` as `monocular`,
//! IGEV-Stereo's volume under `geometry` and its superpixel heads under `superpixel`), and where
//! IGEV-Stereo names a level by another stride (its GRUs `gru04/08/16` are `gru08/16/32`, its
//! context heads `outputs04/08/16` are `outputs08/16/32`, as RAFT-Stereo names them). Our paths
//! also carry the variants of enum modules (`encoder.Separate.fnet`, `conv.Plain`), which the
//! PyTorch loader skips and the official keys lack.

use dgstereo_core::key_notation::Rename;

/// RAFT-Stereo's renames, DEFOM-Stereo's monocular network among them (its DPT heads' names are
/// the prior crate's Depth Anything V2 table, which the family reads after this one).
pub const RAFT_STEREO: &[Rename] = &[
    Rename::new("{outputs08|outputs16}.{#}.0.", "{outputs08|outputs16}.{#}.block."),
    Rename::new("{outputs08|outputs16}.{#}.1.", "{outputs08|outputs16}.{#}.conv."),
    Rename::new("downsample.0.", "downsample."),
    Rename::new("^conv2.0.", "^conv2.block."),
    Rename::new("^conv2.1.", "^conv2.conv."),
    Rename::new("update_block.mask.0.", "update_block.mask.conv1."),
    Rename::new("update_block.mask.2.", "update_block.mask.conv2."),
    // The encoder layout's modules, at the reference's top level.
    Rename::new("^{fnet|cnet|conv2}.", "^encoder.{fnet|cnet|conv2}."),
    // DEFOM-Stereo's Depth Anything V2.
    Rename::new("^defomencoder.depth_anything.", "^monocular."),
];

/// IGEV-Stereo's renames, read before RAFT-Stereo's (which then move `cnet` under `encoder` and
/// name the context heads' and residual blocks' indices). They apply to a model with the geometry
/// encoding volume only: its GRU and context-head names clash with RAFT-Stereo's.
pub const IGEV_STEREO: &[Rename] = &[
    // The image stems' `Sequential` indices.
    Rename::new("^{stem_2|stem_4}.0.", "^{stem_2|stem_4}.block."),
    Rename::new("^{stem_2|stem_4}.1.", "^{stem_2|stem_4}.conv."),
    // The context heads by stride, coarsest first, so that no head moves twice.
    Rename::new("^cnet.outputs16.", "^cnet.outputs32."),
    Rename::new("^cnet.outputs08.", "^cnet.outputs16."),
    Rename::new("^cnet.outputs04.", "^cnet.outputs08."),
    // The superpixel heads' `Sequential` indices.
    Rename::new("^{spx|spx_gru}.0.{weight|bias}$", "^{spx|spx_gru}.{weight|bias}$"),
    Rename::new("^spx_4.0.", "^spx_4.block."),
    Rename::new("^spx_4.1.", "^spx_4.conv."),
    // The GRUs by stride, coarsest first.
    Rename::new("^update_block.gru16.", "^update_block.gru32."),
    Rename::new("^update_block.gru08.", "^update_block.gru16."),
    Rename::new("^update_block.gru04.", "^update_block.gru08."),
    Rename::new("^update_block.mask_feat_4.0.", "^update_block.mask_feat_4.conv."),
    // The geometry encoding volume's modules, and the feature gates' `Sequential` indices.
    Rename::new(
        "^{conv|desc|corr_stem|corr_feature_att|cost_agg|classifier}.",
        "^geometry.{conv|desc|corr_stem|corr_feature_att|cost_agg|classifier}.",
    ),
    Rename::new("corr_feature_att.feat_att.0.", "corr_feature_att.reduce."),
    Rename::new("corr_feature_att.feat_att.1.", "corr_feature_att.expand."),
    Rename::new("feature_att_{*}.feat_att.0.", "feature_att_{*}.reduce."),
    Rename::new("feature_att_{*}.feat_att.1.", "feature_att_{*}.expand."),
    Rename::new("^{spx|spx_2|spx_4|spx_2_gru|spx_gru}.", "^superpixel.{spx|spx_2|spx_4|spx_2_gru|spx_gru}."),
    // The feature pyramid and the stems, beside `cnet` in the encoder layout.
    Rename::new("^{feature|stem_2|stem_4}.", "^encoder.{feature|stem_2|stem_4}."),
];

/// timm's `mobilenetv2_100` (timm 0.5.4) state dict into IGEV-Stereo's feature trunk (paths below
/// the feature network), for the ImageNet weights a training run starts from: IGEV-Stereo's
/// `Feature` regroups timm's stages as `layers = [1, 2, 3, 5, 6]`, so `block0` is stage 0,
/// `block1` stage 1, `block2` stage 2, `block3` stages 3 and 4 and `block4` stage 5; `conv_stem`
/// and `bn1` keep their names.
pub const TIMM_MOBILENET_TRUNK: &[Rename] = &[
    Rename::new("^blocks.0.", "^block0.0."),
    Rename::new("^blocks.1.", "^block1.0."),
    Rename::new("^blocks.2.", "^block2.0."),
    Rename::new("^blocks.3.", "^block3.0."),
    Rename::new("^blocks.4.", "^block3.1."),
    Rename::new("^blocks.5.", "^block4.0."),
];

/// The top-level modules of every encoder layout, which our paths hold under `encoder.<layout>`
/// and files (official and ours) at their top level.
pub const ENCODER_MODULES: [&str; 6] = ["fnet", "cnet", "conv2", "feature", "stem_2", "stem_4"];

/// Whether the loader ignores an official key: one the reference stores twice (`downsample.1.*`,
/// the same BatchNorm as its block's `norm3`), BatchNorm's unused `num_batches_tracked`, and
/// DEFOM-Stereo's `mean` and `std`, the ImageNet constants its encoders apply
/// (`dgstereo_encoder::InputNormalisation`).
pub fn ignored_by_loader(key: &str) -> bool {
    key.ends_with("num_batches_tracked") || key.contains("downsample.1.") || key == "mean" || key == "std"
}

/// The module path of the ignored key `downsample.1.*` where a caller needs one (the training
/// step's gradients name both): `norm3.*`, the module it repeats.
pub fn alias_of_ignored(path: &str) -> String {
    path.replace("downsample.1.", "norm3.")
}
