//! How IGEV-Stereo's state-dict keys name the modules of [`PyramidEncoders`](crate::PyramidEncoders).
//!
//! The pyramid's fields carry the official names (`feature.block3.1.0.conv_pw.weight` is a path
//! as it stands). What differs: the stems' `Sequential` indices (`stem_2.0.` is `stem_2.block.`,
//! `stem_2.1.` is `stem_2.conv.`), the context encoder's heads, which IGEV names after their
//! strides (`outputs04/08/16`) and RAFT-Stereo's encoder one stride coarser (`outputs08/16/32`),
//! and RAFT-Stereo's own renames inside the context encoder (a head's `.0.`/`.1.` is
//! `block`/`conv`, `downsample.0.` is `downsample.`). Enum variants in our paths (`conv.Plain.`)
//! are left out on both sides: the PyTorch loader skips them.

/// Renames from the official keys under `feature.`, `stem_2.`, `stem_4.` and `cnet.` to the paths
/// of [`PyramidEncoders`](crate::PyramidEncoders)' fields, applied in order. Applying
/// RAFT-Stereo's renames afterwards changes nothing.
pub const IGEV_ENCODER_RENAMES: &[(&str, &str)] = &[
    (r"^(stem_2|stem_4)\.0\.", "$1.block."),
    (r"^(stem_2|stem_4)\.1\.", "$1.conv."),
    // Coarsest first, so that no head is renamed twice.
    (r"^cnet\.outputs16\.", "cnet.outputs32."),
    (r"^cnet\.outputs08\.", "cnet.outputs16."),
    (r"^cnet\.outputs04\.", "cnet.outputs08."),
    (r"^cnet\.(outputs08|outputs16)\.(\d+)\.0\.", "cnet.$1.$2.block."),
    (r"^cnet\.(outputs08|outputs16)\.(\d+)\.1\.", "cnet.$1.$2.conv."),
    (r"downsample\.0\.", "downsample."),
    (r"downsample\.1\.", "norm3."),
];

/// Renames from our paths (enum variants removed, RAFT-Stereo's inverse renames of the context
/// encoder applied: `outputs08.0.0.`, `downsample.0.`) back to IGEV's keys, applied in order.
pub const IGEV_ENCODER_INVERSE_RENAMES: &[(&str, &str)] = &[
    (r"^(stem_2|stem_4)\.block\.", "$1.0."),
    (r"^(stem_2|stem_4)\.conv\.", "$1.1."),
    // Finest first, so that no head is renamed twice.
    (r"^cnet\.outputs08\.", "cnet.outputs04."),
    (r"^cnet\.outputs16\.", "cnet.outputs08."),
    (r"^cnet\.outputs32\.", "cnet.outputs16."),
];
