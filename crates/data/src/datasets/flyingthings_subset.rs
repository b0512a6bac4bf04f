//! FlyingThings3D TEST, whole or as RAFT-Stereo's 400-pair validation subset.
//!
//! RAFT-Stereo's `evaluate_stereo.py --dataset things` scores 400 of the TEST pairs, chosen in
//! `core/stereo_datasets.py` (`SceneFlowDatasets._add_things`): the left images
//! `frames_finalpass/TEST/*/*/left/*.png` sorted as path strings, then
//! `np.random.seed(1000); set(np.random.permutation(len(left_images))[:400])`, and the pairs at
//! those indices kept in sorted order. [`flyingthings_test`] lists the same pairs: the same glob,
//! the same sort, NumPy's generator ([`numpy_permutation`]). The indices depend on how many left
//! images the folder holds, so the subset is RAFT-Stereo's exactly when the folder is the complete
//! official TEST split; with fewer than 400 images every pair is kept, as in RAFT-Stereo.

use std::collections::HashSet;
use std::fmt;
use std::path::Path;
use std::str::FromStr;

use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

use super::numpy_permutation::numpy_permutation;
use super::sceneflow::{SceneFlowPass, SceneFlowSubset, sceneflow};
use super::{FileDataset, SampleFiles, ValidRule};

/// The seed RAFT-Stereo draws its FlyingThings3D validation pairs with.
pub const RAFT_STEREO_SUBSET_SEED: u32 = 1000;

/// The number of FlyingThings3D TEST pairs RAFT-Stereo validates on.
pub const RAFT_STEREO_SUBSET_SIZE: usize = 400;

/// Which FlyingThings3D TEST pairs to list.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlyingThingsTestSubset {
    /// Every TEST pair.
    #[default]
    All,
    /// RAFT-Stereo's 400 validation pairs (see the module doc).
    #[serde(rename = "raft-stereo-400")]
    RaftStereo400,
}

impl FlyingThingsTestSubset {
    /// Every subset.
    pub const ALL: [Self; 2] = [Self::All, Self::RaftStereo400];

    /// The subset's name (as in TOML and on the command line).
    pub fn name(self) -> &'static str {
        match self {
            Self::All => "all",
            Self::RaftStereo400 => "raft-stereo-400",
        }
    }
}

impl fmt::Display for FlyingThingsTestSubset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for FlyingThingsTestSubset {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            Error::config(
                "subset",
                format!("unknown FlyingThings3D TEST subset '{s}' (expected all or raft-stereo-400)"),
            )
        })
    }
}

/// Lists FlyingThings3D TEST under `root` (the folder holding `frames_*pass` and `disparity`) in
/// `pass`: every pair, or RAFT-Stereo's 400 (see the module doc). Valid ground truth: `|d| < 512`.
pub fn flyingthings_test(root: &Path, pass: SceneFlowPass, subset: FlyingThingsTestSubset) -> Result<FileDataset> {
    match subset {
        FlyingThingsTestSubset::All => sceneflow(root, SceneFlowSubset::FlyingThingsTest, pass),
        FlyingThingsTestSubset::RaftStereo400 => raft_stereo_subset(root, pass),
    }
}

fn raft_stereo_subset(root: &Path, pass: SceneFlowPass) -> Result<FileDataset> {
    let frames = root.join(pass.folder());
    let lefts = test_left_images(&frames.join("TEST"))?;
    let chosen: HashSet<usize> =
        numpy_permutation(RAFT_STEREO_SUBSET_SEED, lefts.len()).into_iter().take(RAFT_STEREO_SUBSET_SIZE).collect();
    let files = lefts
        .iter()
        .enumerate()
        .filter(|(i, _)| chosen.contains(i))
        .map(|(_, rel)| {
            // rel = TEST/<letter>/<sequence>/left/<frame>.png
            let right = rel.replacen("/left/", "/right/", 1);
            SampleFiles {
                name: rel.clone(),
                group: None,
                left: frames.join(rel),
                right: frames.join(right),
                disparity: Some(root.join("disparity").join(rel).with_extension("pfm")),
                nonoccluded: None,
            }
        })
        .collect();
    Ok(FileDataset { files, rule: ValidRule::Below(512.0) })
}

/// `sorted(glob(TEST/*/*/left/*.png))` relative to the pass folder, `/`-separated; like Python's
/// glob, `*` skips names starting with a dot.
fn test_left_images(test: &Path) -> Result<Vec<String>> {
    if !test.is_dir() {
        return Err(Error::format(test, "FlyingThings3D TEST frames folder not found"));
    }
    let mut lefts = Vec::new();
    for letter in visible_entries(test)?.into_iter().filter(|(_, p)| p.is_dir()) {
        for sequence in visible_entries(&letter.1)?.into_iter().filter(|(_, p)| p.is_dir()) {
            let left = sequence.1.join("left");
            if !left.is_dir() {
                continue;
            }
            for (frame, _) in visible_entries(&left)? {
                if frame.ends_with(".png") {
                    lefts.push(format!("TEST/{}/{}/left/{frame}", letter.0, sequence.0));
                }
            }
        }
    }
    lefts.sort();
    Ok(lefts)
}

fn visible_entries(dir: &Path) -> Result<Vec<(String, std::path::PathBuf)>> {
    let mut entries = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if !name.starts_with('.') {
            entries.push((name, path));
        }
    }
    Ok(entries)
}
