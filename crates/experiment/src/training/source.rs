//! [`DataSource`]: one source of training pairs, an entry of `[[data.sources]]`.

use std::path::PathBuf;

use dgstereo_core::Problem;
use dgstereo_data::SyntheticConfig;
use serde::{Deserialize, Serialize};

use super::scenes::SyntheticScenes;

fn one() -> f64 {
    1.0
}

/// One source of training pairs (an entry of `[[data.sources]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum DataSource {
    /// The procedural generator of the data crate (exact ground truth, unlimited pairs).
    Synthetic {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The scenes' keys (`width`, `height`, `max_disparity`, `textures`, `min_disparity`,
        /// `photos`), shared with the validation set.
        #[serde(flatten)]
        scenes: SyntheticScenes,
        /// A fixed set of this many scenes; unlimited (a new scene per draw) when absent.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        count: Option<usize>,
        /// Share of scenes with a lattice in front (a trellis or fence: thin bars, a repetitive
        /// pattern, the scene seen through its holes), in [0, 1]; default 0.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        lattices: Option<f64>,
    },
    /// SceneFlow (`root` holds `frames_*pass` and `disparity`).
    Sceneflow {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
        /// `flyingthings` (TRAIN), `driving` or `monkaa`.
        #[serde(default = "default_subset")]
        subset: String,
        /// `clean` or `final`.
        #[serde(default = "default_pass")]
        pass: String,
    },
    /// Middlebury 2014 (`root` holds the scene folders).
    Middlebury {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
    },
    /// ETH3D two-view training set.
    Eth3d {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
    },
    /// KITTI 2012 or 2015 (`root` is the `training` folder).
    Kitti {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The dataset folder.
        root: PathBuf,
        /// 2012 or 2015.
        #[serde(default = "default_kitti")]
        version: u32,
    },
    /// A folder of pairs with ground truth beside them (see the data crate's `folder_pairs`).
    Folder {
        /// Share of the batch elements drawn from this source.
        #[serde(default = "one")]
        weight: f64,
        /// The folder.
        root: PathBuf,
        /// Ground truth with holes (LiDAR, KITTI-style PNGs): augment with the sparse augmentor.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        sparse: bool,
    },
}

fn default_subset() -> String {
    "flyingthings".into()
}
fn default_pass() -> String {
    "clean".into()
}
fn default_kitti() -> u32 {
    2015
}

impl DataSource {
    /// Whether the ground truth has holes, so augmentation must move valid points rather than
    /// interpolate (RAFT-Stereo's `sparse=True` sets: KITTI, ETH3D, Middlebury; a folder when it
    /// says so).
    pub fn sparse_ground_truth(&self) -> bool {
        match self {
            Self::Synthetic { .. } | Self::Sceneflow { .. } => false,
            Self::Middlebury { .. } | Self::Eth3d { .. } | Self::Kitti { .. } => true,
            Self::Folder { sparse, .. } => *sparse,
        }
    }
}

impl Default for DataSource {
    fn default() -> Self {
        Self::Synthetic { weight: 1.0, scenes: SyntheticScenes::default(), count: None, lattices: None }
    }
}

impl DataSource {
    /// The source's share of the batch.
    pub fn weight(&self) -> f64 {
        match self {
            Self::Synthetic { weight, .. }
            | Self::Sceneflow { weight, .. }
            | Self::Middlebury { weight, .. }
            | Self::Eth3d { weight, .. }
            | Self::Kitti { weight, .. }
            | Self::Folder { weight, .. } => *weight,
        }
    }
}

impl DataSource {
    /// Everything wrong with the source's values, keys relative to its entry (`weight`,
    /// `lattices`, `photos.share`); the folders of dataset sources are checked where the data
    /// is opened.
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        let w = self.weight();
        if !(w.is_finite() && w >= 0.0) {
            problems.push(Problem::new("weight", format!("{w}: must be finite and >= 0")));
        }
        if let Self::Synthetic { scenes, count, lattices, .. } = self {
            if let Some(p) = lattices.filter(|p| !(0.0..=1.0).contains(p)) {
                problems.push(Problem::new("lattices", format!("{p}: must be a share in [0, 1]")));
            }
            if scenes.width < 16 || scenes.height < 16 {
                problems.push(Problem::new(
                    "",
                    format!("synthetic images of {}x{} are too small (at least 16x16)", scenes.width, scenes.height),
                ));
            }
            problems.extend(scenes.problems());
            if *count == Some(0) {
                problems.push(Problem::new("count", "must be at least 1"));
            }
        }
        problems
    }

    /// The generator's settings of a synthetic source; `None` for the other kinds.
    pub fn synthetic(&self) -> Option<SyntheticConfig> {
        match self {
            Self::Synthetic { scenes, lattices, .. } => Some(scenes.synthetic(*lattices)),
            _ => None,
        }
    }
}
