//! SceneFlow (FlyingThings3D, Driving, Monkaa) folder layouts.
//!
//! Each subset keeps images under `frames_{cleanpass,finalpass}/...` and disparity under
//! `disparity/...` with the same relative path and `.pfm` extension; the views are folders named
//! `left` and `right`:
//! - FlyingThings3D: `frames_cleanpass/{TRAIN,TEST}/{A,B,C}/NNNN/left/NNNN.png`
//! - Driving: `frames_cleanpass/{15,35}mm_focallength/scene_{forwards,backwards}/{fast,slow}/left/NNNN.png`
//! - Monkaa: `frames_cleanpass/<scene>/left/NNNN.png`

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};

use super::{FileDataset, SampleFiles, ValidRule};

/// A SceneFlow subset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFlowSubset {
    /// FlyingThings3D `TRAIN`.
    FlyingThingsTrain,
    /// FlyingThings3D `TEST`.
    FlyingThingsTest,
    /// Driving.
    Driving,
    /// Monkaa.
    Monkaa,
}

/// Rendering pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFlowPass {
    /// `frames_cleanpass`.
    Clean,
    /// `frames_finalpass`.
    Final,
}

impl SceneFlowPass {
    /// The pass's folder: `frames_cleanpass` or `frames_finalpass`.
    pub fn folder(self) -> &'static str {
        match self {
            SceneFlowPass::Clean => "frames_cleanpass",
            SceneFlowPass::Final => "frames_finalpass",
        }
    }
}

pub(super) fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .map(|e| e.map(|e| e.path()).map_err(|e| Error::io(dir, e)))
        .collect::<Result<_>>()?;
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, out)?;
        } else {
            out.push(p);
        }
    }
    Ok(())
}

/// Lists a SceneFlow subset under `root` (the folder holding `frames_*pass` and `disparity`).
///
/// Samples without a right image are skipped; a missing disparity file is listed as is (reading
/// it then fails naming the file). Valid ground truth: `|d| < 512`, as RAFT's dense sets.
pub fn sceneflow(root: &Path, subset: SceneFlowSubset, pass: SceneFlowPass) -> Result<FileDataset> {
    let frames = root.join(pass.folder());
    let start = match subset {
        SceneFlowSubset::FlyingThingsTrain => frames.join("TRAIN"),
        SceneFlowSubset::FlyingThingsTest => frames.join("TEST"),
        _ => frames.clone(),
    };
    if !start.is_dir() {
        return Err(Error::format(&start, "SceneFlow frames folder not found"));
    }
    let mut all = Vec::new();
    walk(&start, &mut all)?;
    let mut files = Vec::new();
    for left in all {
        let in_left = left.parent().and_then(|p| p.file_name()).is_some_and(|n| n == "left");
        let is_img = left.extension().is_some_and(|e| e == "png" || e == "webp" || e == "jpg");
        if !in_left || !is_img {
            continue;
        }
        let dir = left.parent().and_then(Path::parent).unwrap_or(Path::new(""));
        let right = dir.join("right").join(left.file_name().unwrap_or_default());
        if !right.is_file() {
            continue;
        }
        let rel = left.strip_prefix(&frames).unwrap_or(&left).to_path_buf();
        let disparity = root.join("disparity").join(&rel).with_extension("pfm");
        files.push(SampleFiles {
            name: rel.to_string_lossy().replace('\\', "/"),
            group: None,
            left,
            right,
            disparity: Some(disparity),
            nonoccluded: None,
        });
    }
    Ok(FileDataset { files, rule: ValidRule::Below(512.0) })
}
