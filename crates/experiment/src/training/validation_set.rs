//! [`ValidationConfig`]: the held-out synthetic pairs, the `[data.validation]` table.

use dgstereo_core::Problem;
use dgstereo_data::SyntheticConfig;
use serde::{Deserialize, Serialize};

use super::scenes::SyntheticScenes;

/// The validation set (`[data.validation]`): held-out synthetic pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidationConfig {
    /// Number of pairs (0: no validation).
    pub count: usize,
    /// Seed of the first pair; pair `i` is the scene of `seed + i`.
    pub seed: u64,
    /// Update iterations at validation (`valid_iters`).
    pub iters: usize,
    /// The scenes' keys, as a synthetic source's (`width`, `height`, `textures`,
    /// `max_disparity`, `min_disparity`, `photos`: a held-out set rendered with photographs).
    /// The default texture mix `"smooth"` keeps validation numbers comparable with earlier runs.
    #[serde(flatten)]
    pub scenes: SyntheticScenes,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        Self { count: 8, seed: 1 << 40, iters: 32, scenes: SyntheticScenes::default() }
    }
}

impl ValidationConfig {
    /// Everything wrong with the values, keys relative to the `[data.validation]` table.
    pub fn problems(&self) -> Vec<Problem> {
        self.scenes.problems()
    }

    /// The generator's settings for the validation pairs.
    pub fn synthetic(&self) -> SyntheticConfig {
        self.scenes.synthetic(None)
    }
}
