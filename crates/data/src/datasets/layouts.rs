//! Folder layouts of Middlebury 2014, ETH3D two-view, KITTI 2012/2015 and plain folders of pairs.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};

use super::pair_finder::{find_folder_pairs, replace_side_word};
use super::{FileDataset, SampleFiles, ValidRule};

fn subdirs(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    v.sort();
    Ok(v)
}

fn some_file(p: PathBuf) -> Option<PathBuf> {
    p.is_file().then_some(p)
}

fn file_name(p: &Path) -> String {
    p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

/// Middlebury 2014 (and MiddEval3) scenes: every sub-folder of `root` holding `im0.png` and
/// `im1.png`; ground truth `disp0GT.pfm` (inf = unknown) or `disp0.pfm`, non-occlusion mask
/// `mask0nocc.png` (255 = visible in both views). Valid ground truth: finite.
pub fn middlebury2014(root: &Path) -> Result<FileDataset> {
    let mut files = Vec::new();
    for dir in subdirs(root)? {
        let (left, right) = (dir.join("im0.png"), dir.join("im1.png"));
        if !left.is_file() || !right.is_file() {
            continue;
        }
        files.push(SampleFiles {
            name: file_name(&dir),
            group: None,
            left,
            right,
            disparity: some_file(dir.join("disp0GT.pfm")).or_else(|| some_file(dir.join("disp0.pfm"))),
            nonoccluded: some_file(dir.join("mask0nocc.png")),
        });
    }
    Ok(FileDataset { files, rule: ValidRule::Finite })
}

/// ETH3D two-view: scenes in `root/two_view_training/<scene>/{im0,im1}.png` (or
/// `root/two_view_test`, or scene folders directly in `root`), ground truth in
/// `root/two_view_training_gt/<scene>/{disp0GT.pfm, mask0nocc.png}` or beside the images.
/// Valid ground truth: finite and `< 512` (RAFT; occluded pixels included).
pub fn eth3d(root: &Path) -> Result<FileDataset> {
    let images = ["two_view_training", "two_view_test"].iter().map(|d| root.join(d)).find(|p| p.is_dir());
    let (img_root, gt_root) = match images {
        Some(p) => {
            let gt = PathBuf::from(format!("{}_gt", p.display()));
            (p, Some(gt))
        }
        None => (root.to_path_buf(), None),
    };
    let mut files = Vec::new();
    for dir in subdirs(&img_root)? {
        let (left, right) = (dir.join("im0.png"), dir.join("im1.png"));
        if !left.is_file() || !right.is_file() {
            continue;
        }
        let scene = file_name(&dir);
        let gt_dir = gt_root.as_ref().map(|g| g.join(&scene)).filter(|g| g.is_dir()).unwrap_or_else(|| dir.clone());
        files.push(SampleFiles {
            name: scene,
            group: None,
            left,
            right,
            disparity: some_file(gt_dir.join("disp0GT.pfm")),
            nonoccluded: some_file(gt_dir.join("mask0nocc.png")),
        });
    }
    Ok(FileDataset { files, rule: ValidRule::Below(512.0) })
}

/// KITTI version.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KittiVersion {
    /// KITTI 2012: `colored_0`, `colored_1`, `disp_occ`, `disp_noc`.
    K2012,
    /// KITTI 2015: `image_2`, `image_3`, `disp_occ_0`, `disp_noc_0`.
    K2015,
}

/// KITTI stereo: `root` is the `training` (or `testing`) folder; pairs are the `*_10.png` frames.
/// Ground truth `disp_occ` (16-bit PNG /256, 0 = unknown) when present; the non-occluded mask is
/// the `disp_noc` map's non-zero pixels. Valid ground truth: `> 0`.
pub fn kitti(root: &Path, version: KittiVersion) -> Result<FileDataset> {
    let (l, r, occ, noc) = match version {
        KittiVersion::K2012 => ("colored_0", "colored_1", "disp_occ", "disp_noc"),
        KittiVersion::K2015 => ("image_2", "image_3", "disp_occ_0", "disp_noc_0"),
    };
    let left_dir = root.join(l);
    let mut names: Vec<String> = std::fs::read_dir(&left_dir)
        .map_err(|e| Error::io(&left_dir, e))?
        .filter_map(|e| e.ok().map(|e| file_name(&e.path())))
        .filter(|n| n.ends_with("_10.png"))
        .collect();
    names.sort();
    let files = names
        .into_iter()
        .map(|n| SampleFiles {
            name: n.trim_end_matches(".png").to_string(),
            group: None,
            left: left_dir.join(&n),
            right: root.join(r).join(&n),
            disparity: some_file(root.join(occ).join(&n)),
            nonoccluded: some_file(root.join(noc).join(&n)),
        })
        .collect();
    Ok(FileDataset { files, rule: ValidRule::Positive })
}

/// A folder (searched recursively) of pairs, found by the one pair rule of
/// [`super::pair_finder`] (`<x>left<y>.<ext>` / `<x>right<y>.<ext>`, e.g. `desk_left.png`,
/// `left_rgb.png`, or `im0.<ext>` / `im1.<ext>`); a left view without its right view is skipped.
///
/// Ground truth and masks are looked up beside the left image: `<x>disp<y>.{pfm,png,npy}`
/// (the image name with its side word `left` replaced by `disp`), `disp0GT.pfm`/`disp0.pfm` for
/// `im0`, and `mask0nocc.png` or `<x>occ<y>.png`; in a folder holding a single pair also
/// `disp_left.*` and `occlusion.png`. Valid ground truth: finite and `> 0`.
pub fn folder_pairs(root: &Path) -> Result<FileDataset> {
    let pairs: Vec<(PathBuf, PathBuf, String)> = find_folder_pairs(root)?
        .pairs
        .into_iter()
        .map(|p| {
            let stem = p.left.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            (p.left, p.right, stem)
        })
        .collect();
    let mut files = Vec::new();
    for (left, right, stem) in &pairs {
        let dir = left.parent().unwrap_or(Path::new(""));
        let alone = pairs.iter().filter(|(l, _, _)| l.parent() == Some(dir)).count() == 1;
        let mut disp_names: Vec<String> = Vec::new();
        let mut mask_names: Vec<String> = Vec::new();
        match (replace_side_word(stem, "disp"), replace_side_word(stem, "occ")) {
            (Some(disp), Some(occ)) => {
                disp_names.extend(["pfm", "png", "npy"].map(|e| format!("{disp}.{e}")));
                mask_names.push(format!("{occ}.png"));
            }
            // `im0`, the only left stem without a side word.
            _ => {
                disp_names.extend(["disp0GT.pfm", "disp0.pfm", "disp0GT.png", "disp0.npy"].map(String::from));
                mask_names.push("mask0nocc.png".into());
            }
        }
        if alone {
            disp_names.extend(["disp_left.pfm", "disp_left.png", "disp_left.npy"].map(String::from));
            mask_names.extend(["occlusion.png", "mask0nocc.png"].map(String::from));
        }
        let rel = left.strip_prefix(root).unwrap_or(left);
        let name = rel.with_file_name(stem.as_str()).to_string_lossy().replace('\\', "/");
        files.push(SampleFiles {
            name,
            group: None,
            left: left.clone(),
            right: right.clone(),
            disparity: disp_names.iter().find_map(|n| some_file(dir.join(n))),
            nonoccluded: mask_names.iter().find_map(|n| some_file(dir.join(n))),
        });
    }
    Ok(FileDataset { files, rule: ValidRule::Positive })
}
