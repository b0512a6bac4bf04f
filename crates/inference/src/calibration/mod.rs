//! Stereo calibration for depth and point clouds: one [`Calibration`] read from three layouts.
//!
//! - Middlebury `calib.txt` (`cam0=[f 0 cx; 0 f cy; 0 0 1]`, `doffs`, `baseline` in **mm**,
//!   `width`, `height`), read by [`middlebury`];
//! - JSON with `fx`, `fy`, `cx` (or `cx0`, with the right camera's `cx1` giving `doffs = cx1 - cx0`),
//!   `cy` and the baseline as `baseline_meters`/`baseline_m`/`baseline` (**metres**) or
//!   `baseline_mm`; optional `width`, `height`, `doffs`, `depth_range: [near, far]` (metres). This
//!   is the layout of stereodemo's `stereodemo_calibration.json` (OAK-D pairs);
//! - `K.txt`: line 1 the 3x3 intrinsics row-major (9 numbers), line 2 the baseline in **metres**
//!   (FoundationStereo's layout).
//!
//! Design decision: everything is converted to metres and pixels of the calibrated image once. A
//! calibration applies to the image size it was made for; [`Calibration::for_size`] rescales it
//! only for a resize at the same aspect ratio (with a notice) and refuses other sizes, which
//! [`Calibration::adjusted`] fits when the user states the crop or the scale ([`fit`]). Depth is
//! `Z = fx · baseline / (d + doffs)`, `inf` where that is no point in front of the cameras
//! (unknown disparity, or `d + doffs <= 0`); a point is `Z · K⁻¹ · (x, y, 1)` (nalgebra).

pub mod fit;
pub mod middlebury;

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

pub use fit::{Adjustment, Rescaled};
pub use middlebury::{MiddleburyCalib, read_middlebury_calib};

/// Intrinsics of the left camera and the stereo geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    /// The file it was read from.
    pub source: PathBuf,
    /// Left camera matrix `K` (pixels).
    pub intrinsics: Matrix3<f64>,
    /// Baseline in metres.
    pub baseline_m: f64,
    /// `cx_right - cx_left` in pixels (added to the disparity before triangulating).
    pub doffs: f64,
    /// Size of the calibrated images, when the file says.
    pub size: Option<(usize, usize)>,
    /// Depth range the camera is meant for (metres), when the file says.
    pub depth_range: Option<(f64, f64)>,
}

impl Calibration {
    /// Reads a calibration file, its layout chosen by content (see the module doc).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let calib = if text.trim_start().starts_with('{') {
            from_json(path, &text)?
        } else if text.contains("cam0") {
            from_middlebury(path)?
        } else {
            from_k_txt(path, &text)?
        };
        calib.check()?;
        Ok(calib)
    }

    fn check(&self) -> Result<()> {
        let k = &self.intrinsics;
        let bad = |m: String| Error::format(&self.source, format!("calibration {m}"));
        if k.iter().any(|v| !v.is_finite()) || k[(0, 0)] <= 0.0 || k[(1, 1)] <= 0.0 {
            return Err(bad(format!("has invalid focal lengths (fx = {}, fy = {})", k[(0, 0)], k[(1, 1)])));
        }
        if k.try_inverse().is_none() {
            return Err(bad("intrinsics are not invertible".into()));
        }
        if !(self.baseline_m.is_finite() && self.baseline_m > 0.0) {
            return Err(bad(format!("baseline {} is not a positive length", self.baseline_m)));
        }
        if !self.doffs.is_finite() {
            return Err(bad("doffs is not finite".into()));
        }
        Ok(())
    }

    /// Focal length along x (pixels).
    pub fn fx(&self) -> f64 {
        self.intrinsics[(0, 0)]
    }

    /// Depth in metres of disparity `d` (pixels); `inf` when `d` is unknown or `d + doffs <= 0`
    /// (no point in front of the cameras: a negative disparity, or zero at `doffs = 0`), which is
    /// also the invalid value of a PFM map (Middlebury's convention).
    pub fn depth(&self, d: f32) -> f32 {
        let denom = d as f64 + self.doffs;
        if d.is_finite() && denom > 0.0 { (self.fx() * self.baseline_m / denom) as f32 } else { f32::INFINITY }
    }

    /// The 3-D point (metres, camera frame: x right, y down, z forward) of pixel `(x, y)` at depth
    /// `z`, given `k_inv = K⁻¹`.
    pub fn backproject(k_inv: &Matrix3<f64>, x: usize, y: usize, z: f64) -> Vector3<f64> {
        k_inv * Vector3::new(x as f64, y as f64, 1.0) * z
    }
}

fn from_middlebury(path: &Path) -> Result<Calibration> {
    let c = read_middlebury_calib(path)?;
    let k = Matrix3::from_fn(|r, col| c.cam0[r][col]);
    Ok(Calibration {
        source: path.to_path_buf(),
        intrinsics: k,
        baseline_m: c.baseline / 1000.0,
        doffs: c.doffs,
        size: Some((c.width, c.height)),
        depth_range: None,
    })
}

fn from_json(path: &Path, text: &str) -> Result<Calibration> {
    let v: Value =
        serde_json::from_str(text).map_err(|e| Error::format(path, format!("calibration JSON does not parse: {e}")))?;
    let num = |key: &str| v.get(key).and_then(Value::as_f64);
    let need = |keys: &[&str]| -> Result<f64> {
        keys.iter()
            .find_map(|k| num(k))
            .ok_or_else(|| Error::format(path, format!("calibration JSON lacks a number '{}'", keys.join("' or '"))))
    };
    let fx = need(&["fx"])?;
    let fy = num("fy").unwrap_or(fx);
    let cx = need(&["cx", "cx0"])?;
    let cy = need(&["cy"])?;
    let baseline_m = match num("baseline_mm") {
        Some(mm) => mm / 1000.0,
        None => need(&["baseline_meters", "baseline_m", "baseline"])?,
    };
    let doffs = num("doffs").or_else(|| num("cx1").map(|cx1| cx1 - cx)).unwrap_or(0.0);
    let size = match (num("width"), num("height")) {
        (Some(w), Some(h)) if w >= 1.0 && h >= 1.0 => Some((w as usize, h as usize)),
        _ => None,
    };
    let depth_range = match v.get("depth_range") {
        None => None,
        Some(r) => match r.as_array().map(|a| a.iter().filter_map(Value::as_f64).collect::<Vec<_>>()).as_deref() {
            Some([near, far]) if near < far => Some((*near, *far)),
            _ => return Err(Error::format(path, "calibration depth_range must be [near, far] in metres")),
        },
    };
    Ok(Calibration {
        source: path.to_path_buf(),
        intrinsics: Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0),
        baseline_m,
        doffs,
        size,
        depth_range,
    })
}

fn from_k_txt(path: &Path, text: &str) -> Result<Calibration> {
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let numbers = |line: Option<&str>, what: &str| -> Result<Vec<f64>> {
        let line = line.ok_or_else(|| Error::format(path, format!("calibration lacks {what}")))?;
        line.split([' ', '\t', ','])
            .filter(|t| !t.is_empty())
            .map(|t| t.parse::<f64>())
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|_| Error::format(path, format!("calibration {what} is not a list of numbers: '{line}'")))
    };
    let k = numbers(lines.next(), "line 1 (the 9 numbers of the intrinsics K)")?;
    if k.len() != 9 {
        return Err(Error::format(
            path,
            format!(
                "not a calibration file (expected Middlebury calib.txt, JSON, or K.txt whose line 1 has the 9 numbers of K; found {} numbers)",
                k.len()
            ),
        ));
    }
    let b = numbers(lines.next(), "line 2 (the baseline in metres)")?;
    let [baseline_m] = b[..] else {
        return Err(Error::format(path, "calibration line 2 must be one number (the baseline in metres)"));
    };
    Ok(Calibration {
        source: path.to_path_buf(),
        intrinsics: Matrix3::from_row_slice(&k),
        baseline_m,
        doffs: 0.0,
        size: None,
        depth_range: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn middlebury_baseline_is_converted_from_mm() {
        let (_d, p) = write(
            "calib.txt",
            "cam0=[1000 0 100; 0 1000 50; 0 0 1]\ncam1=[1000 0 110; 0 1000 50; 0 0 1]\ndoffs=10\nbaseline=200\nwidth=200\nheight=100\nndisp=64\n",
        );
        let c = Calibration::load(&p).unwrap();
        assert_eq!(c.baseline_m, 0.2);
        // Z = 1000 * 0.2 / (30 + 10) = 5 m.
        assert!((c.depth(30.0) - 5.0).abs() < 1e-6);
        let (half, notice) = c.for_size(100, 50).unwrap();
        assert!((half.depth(15.0) - 5.0).abs() < 1e-6, "the same point at half size");
        assert!(notice.is_some());
        // Negative disparity beyond `doffs`, zero at `doffs = 0` and unknown: no depth.
        assert_eq!(c.depth(-20.0), f32::INFINITY);
        assert_eq!(c.depth(-10.0), f32::INFINITY);
        assert_eq!(c.depth(f32::NAN), f32::INFINITY);
    }

    #[test]
    fn json_and_k_txt_agree() {
        let (_a, j) = write(
            "c.json",
            r#"{"fx": 400, "fy": 400, "cx0": 320, "cx1": 320, "cy": 240, "baseline_meters": 0.1, "extra": 1}"#,
        );
        let (_b, k) = write("K.txt", "400 0 320 0 400 240 0 0 1\n0.1\n");
        let (cj, ck) = (Calibration::load(&j).unwrap(), Calibration::load(&k).unwrap());
        assert_eq!(cj.intrinsics, ck.intrinsics);
        assert!((cj.depth(8.0) - 5.0).abs() < 1e-6 && (ck.depth(8.0) - 5.0).abs() < 1e-6);
        let k_inv = ck.intrinsics.try_inverse().unwrap();
        let p = Calibration::backproject(&k_inv, 720, 240, 5.0);
        assert!((p.x - 5.0).abs() < 1e-9 && p.y.abs() < 1e-9 && (p.z - 5.0).abs() < 1e-9);
    }

    #[test]
    fn broken_files_name_the_file_and_the_problem() {
        for (name, text, needle) in [
            ("a.json", "{\"fx\": 1", "does not parse"),
            ("b.json", "{\"fx\": 1, \"cx\": 1, \"cy\": 1}", "baseline"),
            ("K.txt", "1 2 3\n0.1", "9 numbers"),
            ("K2.txt", "400 0 320 0 400 240 0 0 1\nabc", "line 2"),
            ("c.txt", "cam0=[1 0 0; 0 1 0]\n", "cam0"),
        ] {
            let (_d, p) = write(name, text);
            let e = Calibration::load(&p).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(needle), "{e}");
        }
    }
}
