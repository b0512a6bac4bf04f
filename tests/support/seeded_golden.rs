//! A seeded golden opened for a test: its weights rebuilt from the file's metadata
//! ([`golden_state_dict`]), their keys and shapes, and the official code's recorded tensors.
//! The DEFOM-Stereo and IGEV-Stereo golden tests build their models and inputs through it, so
//! what differs between them is only what they check. Included by path from the tests that use
//! it.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use burn::tensor::Tensor;
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, max_abs_diff};
use dgstereo_model::checkpoint_config::model_from_keys;
use dgstereo_model::official_keys::KeyShape;
use dgstereo_model::seeded::{StateDict, golden_state_dict};
use dgstereo_model::verify::{ReferenceTensors, read_reference};
use dgstereo_model::{ForwardOptions, RaftStereo, checkpoint};

/// One seeded golden file, read.
pub struct SeededGolden {
    /// The file.
    pub path: PathBuf,
    /// The seeded weights under their official keys.
    pub state: StateDict,
    /// Each weight's key and shape.
    pub keys: Vec<KeyShape>,
    /// The official code's recorded tensors.
    pub refs: ReferenceTensors,
}

impl SeededGolden {
    /// Reads the golden at `path`.
    pub fn open(path: &Path) -> Self {
        let (state, _) = golden_state_dict(path).unwrap_or_else(|e| panic!("{e}"));
        let keys = state.iter().map(|t| (t.key.clone(), t.shape.clone())).collect();
        let refs = read_reference(path).unwrap_or_else(|e| panic!("{e}"));
        Self { path: path.to_path_buf(), state, keys, refs }
    }

    /// The recorded 4-D tensor `key` (`input.left`, `disparity.iter3`, ...).
    pub fn tensor(&self, key: &str) -> Tensor<4> {
        let (s, v) = self.refs.get(key).unwrap_or_else(|| panic!("{}: no tensor {key}", self.path.display()));
        from_vec(v.clone(), [s[0], s[1], s[2], s[3]], &default_device())
    }

    /// The model the keys describe, its weights loaded through the official-checkpoint loader.
    pub fn model(&self) -> RaftStereo {
        let (_, model) = model_from_keys(&self.keys, &default_device()).unwrap_or_else(|e| panic!("{e}"));
        checkpoint::load_state_dict(model, &self.state, &self.path).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The largest difference between `model`'s disparity after `iters` iterations on the
    /// recorded pair (with `options`) and the recorded disparity `expected`.
    pub fn disparity_error(
        &self,
        model: &RaftStereo,
        iters: usize,
        options: ForwardOptions<'_>,
        expected: &str,
    ) -> f32 {
        let out = model
            .forward_flow(self.tensor("input.left"), self.tensor("input.right"), None, iters, options)
            .unwrap_or_else(|e| panic!("{e}"));
        max_abs_diff(out.flow_up.last().expect("one prediction at least").clone().neg(), self.tensor(expected))
    }
}

/// The keys and shapes of the seeded weights of the golden at `path`.
pub fn keys_of(path: &Path) -> Vec<KeyShape> {
    let (state, _) = golden_state_dict(path).unwrap_or_else(|e| panic!("{e}"));
    state.into_iter().map(|t| (t.key, t.shape)).collect()
}

/// The `[model]` of the experiment file `experiments/zoo/NAME`.
pub fn zoo_model(name: &str) -> dgstereo_model::ModelConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/zoo").join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let table: toml::Table = toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    table["model"].clone().try_into().unwrap_or_else(|e| panic!("{}: [model]: {e}", path.display()))
}
