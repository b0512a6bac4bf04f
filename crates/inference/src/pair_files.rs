//! One pair from files to files: read both views, fit the calibration to their size, predict,
//! write the requested outputs ([`crate::outputs`]) and report what happened ([`PairReport`]);
//! what `dgstereo infer` does for each pair it names.
//!
//! Design decision: a pair's failure is its own. Every problem of one pair (an unreadable or
//! truncated file, views of different sizes, a calibration that does not fit them, a panic inside
//! the model) comes back as that pair's error, naming its file, so the caller goes on with the
//! other pairs. A panic is caught here and becomes [`Error::Internal`] under the left image's
//! name; keeping the panic's message off the terminal is the caller's (a process-wide hook).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::Instant;

use dgstereo_core::{Error, Result};
use dgstereo_data::datasets::pair_list::PairPaths;
use dgstereo_data::load_rgb;

use crate::calibration::{Adjustment, Calibration, Rescaled};
use crate::engine::{Engine, RunInfo, check_same_size};
use crate::options::PredictOptions;
use crate::outputs::{OutputOptions, calibration_beside, write_outputs};

/// What every pair of a run shares: the model, its options, the outputs and the calibration.
pub struct PairFiles<'a> {
    /// The loaded model.
    pub engine: &'a Engine,
    /// The options of each prediction.
    pub options: &'a PredictOptions,
    /// The output folder and kinds.
    pub outputs: &'a OutputOptions,
    /// The calibration of every pair; `None`: the file beside each left image
    /// ([`calibration_beside`]), where a kind needs one.
    pub calibration: Option<&'a Calibration>,
    /// How the pairs were made from the calibrated images.
    pub adjustment: Adjustment,
}

/// What one pair gave.
#[derive(Clone, Debug)]
pub struct PairReport {
    /// The left image's size, `(width, height)`.
    pub size: (usize, usize),
    /// What the prediction did (network size, cost volume, left-right check, prior time).
    pub info: RunInfo,
    /// Seconds from reading the files to the last output written.
    pub seconds: f64,
    /// The files written, in the order of the kinds.
    pub written: Vec<PathBuf>,
    /// Pixels whose depth is `inf` (disparity unknown, or no point in front of the cameras);
    /// 0 without a calibration.
    pub without_depth: usize,
    /// The notice of a calibration rescaled to the pair's size.
    pub rescaled: Option<Rescaled>,
}

impl PairFiles<'_> {
    /// Reads, predicts and writes `pair`.
    ///
    /// # Errors
    /// The pair's problem, naming its file: reading either view, views of different sizes
    /// (under both names), a calibration missing or not fitting (an unstated crop or scale is
    /// named by its fields, `calib_crop` and `calib_scale`), the prediction (under both names),
    /// writing an output; a panic is [`Error::Internal`] under the left image's name.
    pub fn run(&self, pair: &PairPaths) -> Result<PairReport> {
        match catch_unwind(AssertUnwindSafe(|| self.run_unguarded(pair))) {
            Ok(result) => result,
            Err(panic) => {
                let internal = Error::Internal(Error::panic_message(&*panic).replace(['\n', '\r'], " "));
                Err(internal.context(pair.left.display().to_string()))
            }
        }
    }

    fn run_unguarded(&self, pair: &PairPaths) -> Result<PairReport> {
        let start = Instant::now();
        let left = load_rgb(&pair.left)?;
        let right = load_rgb(&pair.right)?;
        let both = || format!("{} + {}", pair.left.display(), pair.right.display());
        check_same_size(&left, &right).map_err(|e| e.context(both()))?;
        let (calib, rescaled) = if self.outputs.kinds.iter().any(|k| k.needs_calibration()) {
            let loaded = calibration_for(&pair.left, self.calibration)?;
            let (calib, rescaled) =
                loaded.adjusted(&self.adjustment, left.width, left.height).map_err(|e| match e {
                    Error::Shape(m) if self.adjustment.is_none() => {
                        Error::Shape(format!("{m}: `calib_crop` and/or `calib_scale`"))
                    }
                    e => e,
                })?;
            (Some(calib), rescaled)
        } else {
            (None, None)
        };
        let prediction = self.engine.predict(&left, &right, &pair.name, self.options).map_err(|e| e.context(both()))?;
        let (disp, info) = (prediction.disparity, prediction.info);
        let written = write_outputs(self.outputs, &pair.name, &left, &disp, calib.as_ref(), info.rejected.as_ref())?;
        let without_depth =
            calib.as_ref().map_or(0, |c| disp.data.iter().filter(|d| c.depth(**d).is_infinite()).count());
        let seconds = start.elapsed().as_secs_f64();
        Ok(PairReport { size: (left.width, left.height), info, seconds, written, without_depth, rescaled })
    }
}

/// The calibration of the pair whose left image is `left`: `global` when given, else the file
/// beside the image.
fn calibration_for(left: &Path, global: Option<&Calibration>) -> Result<Calibration> {
    if let Some(c) = global {
        return Ok(c.clone());
    }
    match calibration_beside(left) {
        Some(p) => Calibration::load(&p),
        None => Err(Error::config(
            "calib",
            format!("{}: depth and ply outputs need a calibration (or put calib.txt beside the image)", left.display()),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pair_without_calibration_names_its_image_and_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let left = dir.path().join("scene_left.png");
        let e = calibration_for(&left, None).unwrap_err();
        assert!(matches!(&e, Error::Config(p) if p.key == "calib" && p.reason.contains("scene_left.png")), "{e}");
        std::fs::write(dir.path().join("K.txt"), "500 0 100 0 500 80 0 0 1\n0.1\n").unwrap();
        let found = calibration_for(&left, None).unwrap();
        assert_eq!(found.source, dir.path().join("K.txt"));
        assert_eq!(calibration_for(&left, Some(&found)).unwrap().source, found.source);
    }
}
