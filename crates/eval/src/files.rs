//! Scoring disparity files: the library side of `dgstereo metrics --pred P --gt G [--mask M]
//! [--max-disp D]`.

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_data::{load_mask, read_disparity};

use crate::metrics::{Metrics, ValidOptions, accumulate};

/// Scores the prediction file against the ground-truth file.
///
/// `pred` and `gt` are disparity files (`.pfm`, KITTI 16-bit `.png` (/256), `.npy`); `mask` is a
/// picture whose non-zero pixels are kept. Errors name the file at fault (unreadable, malformed,
/// or of another size than the ground truth).
pub fn metrics_for_files(pred: &Path, gt: &Path, mask: Option<&Path>, max_disp: Option<f32>) -> Result<Metrics> {
    let g = read_disparity(gt)?;
    let p = read_disparity(pred)?;
    if (p.width, p.height) != (g.width, g.height) {
        return Err(Error::format(
            pred,
            format!(
                "prediction is {}x{} but the ground truth {} is {}x{}",
                p.width,
                p.height,
                gt.display(),
                g.width,
                g.height
            ),
        ));
    }
    let m = match mask {
        Some(path) => {
            let m = load_mask(path)?;
            if (m.width, m.height) != (g.width, g.height) {
                return Err(Error::format(
                    path,
                    format!(
                        "mask is {}x{} but the ground truth {} is {}x{}",
                        m.width,
                        m.height,
                        gt.display(),
                        g.width,
                        g.height
                    ),
                ));
            }
            Some(m)
        }
        None => None,
    };
    Ok(accumulate(&p, &g, m.as_ref(), ValidOptions { max_disp })?.metrics())
}

/// The JSON object printed by `dgstereo metrics`: keys `epe`, `bad-0.5`, `bad-1`, `bad-2`,
/// `bad-3`, `bad-4`, `d1-all` (numbers, percentages 0..100; `null` when nothing is valid) and
/// `valid_pixels` (integer). See [`metrics_for_files`].
pub fn metrics_json(pred: &Path, gt: &Path, mask: Option<&Path>, max_disp: Option<f32>) -> Result<serde_json::Value> {
    Ok(metrics_for_files(pred, gt, mask, max_disp)?.to_json())
}
