//! The state-dict keys of official checkpoints (RAFT-Stereo, DEFOM-Stereo, IGEV-Stereo) and of
//! our own files, and how they map onto our module paths.
//!
//! Design decision: every difference between an official key and our path is written once, in
//! [`renames`] (one table per model family and the one rule for the keys the loader ignores);
//! loading (official key to our path) and listing or saving in the official layout (our path
//! to the official key) both derive from it ([`notation`]), so the two directions cannot
//! drift apart. The notation is core's (`dgstereo_core::key_notation`), shared with the prior
//! crate, whose Depth Anything V2 table (the DPT heads' `Sequential` indices) the RAFT-Stereo
//! family reads for DEFOM-Stereo's monocular network. Our own safetensors files keep the reference's top-level keys for the encoder
//! layout's modules ([`TO_FILE`], [`from_file`]).
//!
//! [`pth_keys`] lists a `.pth` file's tensors as the file names them, without the
//! `DataParallel` prefix `module.`. [`model_official_keys`] lists the keys an official
//! checkpoint of a model's architecture holds, derived from the model's paths.

pub mod renames;

use std::path::Path;

use burn::store::{BurnToPyTorchAdapter, KeyRemapper, ModuleSnapshot, ModuleStore, PytorchStore};
use dgstereo_core::{Error, Result};

pub use dgstereo_core::key_notation::Rename;
use dgstereo_core::key_notation::{self as notation, apply};
pub use renames::{ENCODER_MODULES, IGEV_STEREO, RAFT_STEREO, TIMM_MOBILENET_TRUNK, ignored_by_loader};

use dgstereo_prior::depth_anything::checkpoint::KEY_RENAMES as DEPTH_ANYTHING_V2;

use crate::RaftStereo;

/// A state-dict key and its tensor's shape.
pub type KeyShape = (String, Vec<usize>);

/// A family of official checkpoints, which decides the renames between their keys and our paths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// RAFT-Stereo and DEFOM-Stereo ([`RAFT_STEREO`], then Depth Anything V2's DPT names).
    RaftStereo,
    /// IGEV-Stereo ([`IGEV_STEREO`], then [`RAFT_STEREO`]).
    IgevStereo,
}

impl Family {
    /// The family of `model`'s architecture: IGEV-Stereo's for a model with the geometry
    /// encoding volume.
    pub fn of(model: &RaftStereo) -> Self {
        if model.geometry.is_some() { Self::IgevStereo } else { Self::RaftStereo }
    }

    /// The family's renames, in the order loading applies them.
    pub fn renames(self) -> Vec<Rename> {
        match self {
            Self::RaftStereo => RAFT_STEREO.iter().chain(DEPTH_ANYTHING_V2).copied().collect(),
            Self::IgevStereo => IGEV_STEREO.iter().chain(RAFT_STEREO).chain(DEPTH_ANYTHING_V2).copied().collect(),
        }
    }

    /// The patterns that turn an official key (with or without `module.`) into our module path
    /// without enum variants, as the PyTorch loader matches it.
    pub fn load_patterns(self) -> Vec<(String, String)> {
        let mut patterns = vec![(r"^module\.".to_string(), String::new())];
        patterns.extend(notation::load_patterns(&self.renames()));
        patterns
    }

    /// The patterns that turn our module path (enum variants and all) into the official key.
    pub fn save_patterns(self) -> Vec<(String, String)> {
        // Enum modules (`Norm::Batch`, `encoder.Separate`) add their variant to our paths.
        let mut patterns = vec![(r"\.[A-Z][A-Za-z0-9]*\.".to_string(), ".".to_string())];
        patterns.extend(notation::save_patterns(&self.renames()));
        patterns
    }

    /// Our module path (enum variants left out) of an official key, with or without `module.`.
    pub fn module_path_of_official_key(self, key: &str) -> String {
        apply(&remapper(self.load_patterns()), key)
    }

    /// The official key (without `module.`) of one of our module paths.
    pub fn official_key_of_module_path(self, path: &str) -> String {
        apply(&remapper(self.save_patterns()), path)
    }
}

fn remapper(patterns: Vec<(String, String)>) -> KeyRemapper {
    KeyRemapper::from_patterns(patterns).expect("the renames' notation makes valid patterns")
}

/// The pattern and replacement that turn a module path into its key in our files: the encoder
/// layout's variant dropped (`encoder.Separate.fnet.` is `fnet.`).
pub const TO_FILE: (&str, &str) = (r"^encoder\.[A-Z][A-Za-z0-9]*\.", "");

/// The pattern and replacement that turn a key of our files into a module path of `model`: the
/// encoder layout's modules ([`ENCODER_MODULES`]) under `encoder.<the model's layout>.`.
pub fn from_file(model: &RaftStereo) -> (String, String) {
    (format!(r"^({})\.", ENCODER_MODULES.join("|")), format!("encoder.{}.${{1}}.", model.encoder.variant_name()))
}

/// The keys (official names, no `module.` prefix) and shapes an official checkpoint of
/// `model`'s architecture holds, the ones the loader ignores left out, sorted by key.
pub fn model_official_keys(model: &RaftStereo) -> Vec<KeyShape> {
    let tensors = model.collect(None, Some(Box::new(BurnToPyTorchAdapter)), false);
    let save = remapper(Family::of(model).save_patterns());
    let mut keys: Vec<KeyShape> = tensors.iter().map(|t| (apply(&save, &t.name), t.shape.to_vec())).collect();
    keys.sort();
    keys
}

/// Every tensor of an official `.pth` checkpoint: its key (the `module.` prefix removed) and
/// shape, sorted by key.
pub fn pth_keys(path: &Path) -> Result<Vec<KeyShape>> {
    if !path.is_file() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file")));
    }
    let mut store = PytorchStore::from_file(path).map_indices_contiguous(false);
    let tensors = store
        .get_all_tensors()
        .map_err(|e| Error::Checkpoint { path: path.into(), message: format!("cannot read checkpoint: {e}") })?;
    let mut keys: Vec<KeyShape> =
        tensors.iter().map(|(k, t)| (k.strip_prefix("module.").unwrap_or(k).to_string(), t.shape.to_vec())).collect();
    keys.sort();
    Ok(keys)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both sides of every rename hold the same braces in the same order, so each direction
    /// carries every shared part across.
    #[test]
    fn both_sides_of_every_rename_share_their_braces() {
        for rename in RAFT_STEREO.iter().chain(IGEV_STEREO) {
            assert_eq!(Rename::braces(rename.official), Rename::braces(rename.ours), "{rename:?}");
            for side in [rename.official, rename.ours] {
                let literal = side.trim_start_matches('^').trim_end_matches('$');
                let plain = literal.chars().all(|c| c.is_ascii_alphanumeric() || "._{}|#*".contains(c));
                assert!(plain, "{side}: the notation's literals are names, digits and dots");
            }
        }
    }

    /// Keys of each family and their paths, both ways: a context head moves a stride, a stem and
    /// a superpixel head leave their `Sequential` indices, DEFOM-Stereo's monocular network moves.
    #[test]
    fn keys_and_paths_map_both_ways() {
        let cases = [
            (Family::RaftStereo, "cnet.outputs08.0.1.weight", "encoder.cnet.outputs08.0.conv.weight"),
            (Family::RaftStereo, "fnet.layer2.0.downsample.0.bias", "encoder.fnet.layer2.0.downsample.bias"),
            (Family::RaftStereo, "conv2.0.conv1.weight", "encoder.conv2.block.conv1.weight"),
            (Family::RaftStereo, "update_block.mask.2.bias", "update_block.mask.conv2.bias"),
            (
                Family::RaftStereo,
                "defomencoder.depth_anything.depth_head.resize_layers.3.weight",
                "monocular.depth_head.downsample_2x.weight",
            ),
            (Family::IgevStereo, "cnet.outputs04.0.0.conv1.weight", "encoder.cnet.outputs08.0.block.conv1.weight"),
            (Family::IgevStereo, "update_block.gru04.convz.weight", "update_block.gru08.convz.weight"),
            (Family::IgevStereo, "update_block.gru16.convr.weight", "update_block.gru32.convr.weight"),
            (Family::IgevStereo, "stem_2.1.weight", "encoder.stem_2.conv.weight"),
            (Family::IgevStereo, "spx_gru.0.bias", "superpixel.spx_gru.bias"),
            (Family::IgevStereo, "spx_4.0.conv.weight", "superpixel.spx_4.block.conv.weight"),
            (Family::IgevStereo, "feature.conv_stem.weight", "encoder.feature.conv_stem.weight"),
            (
                Family::IgevStereo,
                "cost_agg.feature_att_up_16.feat_att.1.bias",
                "geometry.cost_agg.feature_att_up_16.expand.bias",
            ),
            (
                Family::IgevStereo,
                "corr_feature_att.feat_att.0.bn.running_var",
                "geometry.corr_feature_att.reduce.bn.running_var",
            ),
        ];
        for (family, official, ours) in cases {
            assert_eq!(family.module_path_of_official_key(official), ours, "{official}");
            assert_eq!(family.module_path_of_official_key(&format!("module.{official}")), ours, "module.{official}");
            assert_eq!(family.official_key_of_module_path(ours), official, "{ours}");
        }
        // Enum variants in our paths are left out of the official key.
        let path = "encoder.Separate.cnet.norm1.Batch.weight";
        assert_eq!(Family::RaftStereo.official_key_of_module_path(path), "cnet.norm1.weight");
    }
}
