//! The files written for one pair named `NAME` in an output folder (`dgstereo infer --save
//! KINDS`), one [`SaveKind`] a file.
//!
//! | kind | file | content |
//! |---|---|---|
//! | `pfm` | `NAME_disparity.pfm` | float32 disparity (px) of the left view |
//! | `npy` | `NAME_disparity.npy` | the same as a `(H, W)` float32 NumPy array |
//! | `png16` | `NAME_disparity_png16.png` | KITTI-style 16-bit PNG, disparity × 256, 0 = invalid |
//! | `color` | `NAME_disparity_color.png` | turbo colour map with a legend of its range (px) |
//! | `depth` | `NAME_depth.pfm` | float32 depth in metres, `inf` where the disparity is unknown or `d + doffs <= 0` (negative: no point in front of the cameras) (needs calibration) |
//! | `ply` | `NAME_points.ply` | coloured point cloud, see [`crate::pointcloud`] (needs calibration) |
//! | `rejected` | `NAME_rejected.png` | 255 where the left-right check replaced the disparity, else 0 (needs the check) |
//!
//! Design decision: the kind decides the suffix, the pair decides `NAME` (see
//! [`dgstereo_data::datasets::pair_list`]), so two kinds or two pairs never write the same file.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use dgstereo_data::visualize::{colorize, display_range, side_by_side};
use dgstereo_data::{DisparityMap, Mask, RgbImage, save_mask, save_rgb, write_disparity};

use crate::calibration::Calibration;
use crate::pointcloud::{PlyEncoding, depth_map, point_cloud, write_ply};

/// One kind of output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum SaveKind {
    /// Float disparity as PFM.
    Pfm,
    /// Float disparity as `.npy`.
    Npy,
    /// KITTI 16-bit PNG disparity (× 256).
    Png16,
    /// Turbo colour picture with a legend.
    Color,
    /// The left image and the colour picture side by side (a quick look, for reports).
    Preview,
    /// Depth in metres as PFM (needs calibration); `inf` where the disparity is unknown or
    /// negative beyond `doffs`.
    Depth,
    /// Coloured point cloud as PLY (needs calibration).
    Ply,
    /// The pixels the left-right check replaced, as a PNG mask (needs --lr-check).
    Rejected,
}

impl SaveKind {
    /// Whether the kind needs a calibration.
    pub fn needs_calibration(self) -> bool {
        matches!(self, SaveKind::Depth | SaveKind::Ply)
    }

    /// The file this kind writes for the pair `name`.
    pub fn file_name(self, name: &str) -> String {
        match self {
            SaveKind::Pfm => format!("{name}_disparity.pfm"),
            SaveKind::Npy => format!("{name}_disparity.npy"),
            SaveKind::Png16 => format!("{name}_disparity_png16.png"),
            SaveKind::Color => format!("{name}_disparity_color.png"),
            SaveKind::Preview => format!("{name}_preview.png"),
            SaveKind::Depth => format!("{name}_depth.pfm"),
            SaveKind::Ply => format!("{name}_points.ply"),
            SaveKind::Rejected => format!("{name}_rejected.png"),
        }
    }
}

/// How outputs are written.
#[derive(Clone, Debug)]
pub struct OutputOptions {
    /// Output folder.
    pub dir: PathBuf,
    /// Kinds to write.
    pub kinds: Vec<SaveKind>,
    /// Farthest point kept in point clouds (metres); `None`: the calibration's depth range, else
    /// the depth of a one-pixel disparity.
    pub max_depth: Option<f64>,
    /// PLY encoding.
    pub ply: PlyEncoding,
}

impl OutputOptions {
    /// The farthest depth kept for `calib` (see [`OutputOptions::max_depth`]).
    pub fn max_depth_for(&self, calib: &Calibration) -> f64 {
        self.max_depth.or(calib.depth_range.map(|(_, far)| far)).unwrap_or_else(|| calib.depth(1.0) as f64)
    }
}

/// Writes the requested outputs of one pair; returns the files written. `calib` must be given
/// (already fitted to the image, see [`Calibration::adjusted`]) when a kind needs it, and
/// `rejected` (the left-right check's mask) for `rejected`.
///
/// # Errors
/// A file that cannot be written, or a kind without what it needs (keyed `calib` or
/// `lr_check`).
pub fn write_outputs(
    opts: &OutputOptions,
    name: &str,
    left: &RgbImage,
    disp: &DisparityMap,
    calib: Option<&Calibration>,
    rejected: Option<&Mask>,
) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let mut depth: Option<DisparityMap> = None;
    for &kind in &opts.kinds {
        let path = opts.dir.join(kind.file_name(name));
        match kind {
            SaveKind::Pfm | SaveKind::Npy | SaveKind::Png16 => write_disparity(&path, disp)?,
            SaveKind::Color => save_rgb(&path, &colorize(disp, display_range(disp), true))?,
            SaveKind::Preview => save_rgb(&path, &side_by_side(&[left, &colorize(disp, display_range(disp), false)]))?,
            SaveKind::Rejected => {
                let rejected = rejected
                    .ok_or_else(|| Error::config("lr_check", "the rejected mask needs the left-right check"))?;
                save_mask(&path, rejected)?;
            }
            SaveKind::Depth | SaveKind::Ply => {
                let calib = calib.ok_or_else(|| Error::config("calib", "depth and point clouds need a calibration"))?;
                let depth = depth.get_or_insert_with(|| depth_map(disp, calib));
                if kind == SaveKind::Depth {
                    write_disparity(&path, depth)?;
                } else {
                    let cloud = point_cloud(depth, left, calib, opts.max_depth_for(calib))?;
                    write_ply(&path, &cloud, opts.ply)?;
                }
            }
        }
        written.push(path);
    }
    Ok(written)
}

/// A calibration beside an image (`calib.txt`, as Middlebury scenes have, or `K.txt`), if any.
pub fn calibration_beside(image: &Path) -> Option<PathBuf> {
    let dir = image.parent()?;
    ["calib.txt", "K.txt"].iter().map(|n| dir.join(n)).find(|p| p.is_file())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_kind_writes_its_own_file_and_refuses_without_what_it_needs() {
        let dir = tempfile::tempdir().unwrap();
        let kinds = vec![SaveKind::Pfm, SaveKind::Npy, SaveKind::Png16, SaveKind::Color, SaveKind::Preview];
        let opts = OutputOptions { dir: dir.path().to_path_buf(), kinds, max_depth: None, ply: PlyEncoding::Ascii };
        let disp = DisparityMap { width: 8, height: 6, data: (0..48).map(|i| 1.0 + (i % 8) as f32).collect() };
        let left = RgbImage::new(8, 6);
        let written = write_outputs(&opts, "desk", &left, &disp, None, None).unwrap();
        let names: Vec<String> =
            written.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
        assert_eq!(
            names,
            [
                "desk_disparity.pfm",
                "desk_disparity.npy",
                "desk_disparity_png16.png",
                "desk_disparity_color.png",
                "desk_preview.png"
            ]
        );
        assert!(written.iter().all(|p| p.is_file()));
        assert_eq!(dgstereo_data::read_disparity(&written[0]).unwrap().data, disp.data);
        for (kind, key) in [(SaveKind::Depth, "calib"), (SaveKind::Ply, "calib"), (SaveKind::Rejected, "lr_check")] {
            let opts = OutputOptions { kinds: vec![kind], ..opts.clone() };
            let e = write_outputs(&opts, "desk", &left, &disp, None, None).unwrap_err();
            assert!(matches!(&e, Error::Config(p) if p.key == key), "{kind:?}: {e}");
            assert_eq!(kind.needs_calibration(), key == "calib");
        }
    }
}
