//! MiddEval3 (Middlebury v3) training splits, read from the MiddEval3 folder and a split, as
//! RAFT-Stereo's `Middlebury` reader does.
//!
//! The download unpacks into `MiddEval3/training{Q,H,F}/<scene>/{im0.png, im1.png, disp0GT.pfm,
//! mask0nocc.png}` (quarter, half and full resolution), and RAFT-Stereo adds
//! `MiddEval3/official_train.txt`, one scene name a line. [`middeval3`] takes `root` as the
//! MiddEval3 folder (or the folder holding it, RAFT-Stereo's `datasets/Middlebury`, or the split
//! folder itself) and lists the split's scenes; where `official_train.txt` exists only the scenes
//! it names are kept, and each must be there. RAFT-Stereo takes the scene names from `trainingF`
//! for every split; they are read from the split's own folder here, so a download of one split
//! suffices (with the complete download both give the same 15 scenes). Valid ground truth:
//! finite (inf marks unknown pixels).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

use super::FileDataset;
use super::layouts::middlebury2014;

/// A MiddEval3 resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum MiddleburySplit {
    /// Quarter resolution (`trainingQ`).
    #[serde(alias = "q")]
    Q,
    /// Half resolution (`trainingH`), the paper's Middlebury-H.
    #[serde(alias = "h")]
    H,
    /// Full resolution (`trainingF`).
    #[serde(alias = "f")]
    F,
}

impl MiddleburySplit {
    /// The three splits, smallest first.
    pub const ALL: [Self; 3] = [Self::Q, Self::H, Self::F];

    /// `Q`, `H` or `F`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Q => "Q",
            Self::H => "H",
            Self::F => "F",
        }
    }

    /// The split's training folder: `trainingQ`, `trainingH` or `trainingF`.
    pub fn folder(self) -> String {
        format!("training{}", self.name())
    }
}

impl fmt::Display for MiddleburySplit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for MiddleburySplit {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| Error::config("split", format!("unknown MiddEval3 split '{s}' (expected Q, H or F)")))
    }
}

/// The MiddEval3 split folders `dir` holds (`dir` is then a MiddEval3 folder).
pub fn middeval3_splits_in(dir: &Path) -> Vec<MiddleburySplit> {
    MiddleburySplit::ALL.into_iter().filter(|s| dir.join(s.folder()).is_dir()).collect()
}

/// Lists the scenes of `split` (see the module doc for `root` and the scene list).
pub fn middeval3(root: &Path, split: MiddleburySplit) -> Result<FileDataset> {
    let split_dir = split_folder(root, split)?;
    let mut dataset = middlebury2014(&split_dir)?;
    if dataset.files.is_empty() {
        return Err(Error::format(&split_dir, "no scene folder with im0.png and im1.png (MiddEval3)"));
    }
    let list = split_dir.parent().map(|p| p.join("official_train.txt")).filter(|p| p.is_file());
    if let Some(list) = list {
        let text = std::fs::read_to_string(&list).map_err(|e| Error::io(&list, e))?;
        let scenes: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
        if let Some(missing) = scenes.iter().find(|s| !dataset.files.iter().any(|f| f.name == **s)) {
            return Err(Error::format(
                &list,
                format!("names scene '{missing}', which {} does not hold", split_dir.display()),
            ));
        }
        dataset.files.retain(|f| scenes.contains(&f.name.as_str()));
    }
    Ok(dataset)
}

/// The split's folder under `root`: `root/training<S>`, `root/MiddEval3/training<S>`, or `root`
/// itself when it is that folder.
fn split_folder(root: &Path, split: MiddleburySplit) -> Result<PathBuf> {
    let folder = split.folder();
    for candidate in [root.join(&folder), root.join("MiddEval3").join(&folder)] {
        if candidate.is_dir() {
            return Ok(candidate);
        }
    }
    let name = root.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    if name == folder && root.is_dir() {
        return Ok(root.to_path_buf());
    }
    let found = middeval3_splits_in(root);
    let message = if let Some(other) = MiddleburySplit::ALL.into_iter().find(|s| s.folder() == name) {
        format!("this is MiddEval3's {} split, not {folder}: give the MiddEval3 folder that holds {folder}/", other)
    } else if !found.is_empty() {
        let names: Vec<String> = found.iter().map(|s| s.folder()).collect();
        format!("no {folder}/ in this MiddEval3 folder (it holds {})", names.join(", "))
    } else {
        format!("expected the MiddEval3 folder holding {folder}/ (or the {folder} folder itself)")
    };
    Err(Error::format(root, message))
}
