//! Per-pixel disparity error metrics.
//!
//! A pixel is **valid** when its ground truth is finite and `> 0`, the mask (if any) is set, and
//! the ground truth is below `max_disp` (if given). On valid pixels, with `e = |pred - gt|`:
//! - `epe`: mean of `e` (pixels);
//! - `bad-T` for `T` in 0.5, 1, 2, 3, 4: percentage (0..100) of valid pixels with `e > T`;
//! - `d1-all`: KITTI's outlier rate, percentage with `e > 3` **and** `e > 0.05 · gt`.
//!
//! A non-finite prediction counts as a prediction of 0 (its error is `gt`). With no valid pixel
//! the metrics are NaN (JSON `null`) and `valid_pixels` is 0.

use serde::{Deserialize, Serialize};

use dgstereo_core::{Error, Result};
use dgstereo_data::{DisparityMap, Mask};

/// The `bad-T` thresholds, in pixels.
pub const BAD_THRESHOLDS: [f32; 5] = [0.5, 1.0, 2.0, 3.0, 4.0];

/// The metric names, in output order (keys of the JSON object, CSV columns).
pub const METRIC_NAMES: [&str; 7] = ["epe", "bad-0.5", "bad-1", "bad-2", "bad-3", "bad-4", "d1-all"];

/// Which pixels count, beyond "ground truth finite and > 0".
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ValidOptions {
    /// Only pixels with ground truth below this.
    pub max_disp: Option<f32>,
}

/// Running sums from which metrics are computed; add them up to pool over images.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MetricSums {
    /// Number of valid pixels.
    pub valid_pixels: u64,
    /// Sum of absolute errors.
    pub abs_error: f64,
    /// Counts of errors above each of [`BAD_THRESHOLDS`].
    pub bad: [u64; 5],
    /// Count of KITTI D1 outliers.
    pub d1: u64,
}

impl MetricSums {
    /// Adds one valid pixel.
    #[inline]
    pub fn add(&mut self, pred: f32, gt: f32) {
        let p = if pred.is_finite() { pred } else { 0.0 };
        let e = (p - gt).abs();
        self.valid_pixels += 1;
        self.abs_error += f64::from(e);
        for (count, t) in self.bad.iter_mut().zip(BAD_THRESHOLDS) {
            *count += u64::from(e > t);
        }
        self.d1 += u64::from(e > 3.0 && e > 0.05 * gt);
    }

    /// Adds another set of sums (pooling).
    pub fn merge(&mut self, other: &MetricSums) {
        self.valid_pixels += other.valid_pixels;
        self.abs_error += other.abs_error;
        for (a, b) in self.bad.iter_mut().zip(other.bad) {
            *a += b;
        }
        self.d1 += other.d1;
    }

    /// The metrics of these sums.
    pub fn metrics(&self) -> Metrics {
        let n = self.valid_pixels as f64;
        let pct = |c: u64| {
            if n > 0.0 { 100.0 * c as f64 / n } else { f64::NAN }
        };
        Metrics {
            epe: if n > 0.0 { self.abs_error / n } else { f64::NAN },
            bad_0_5: pct(self.bad[0]),
            bad_1: pct(self.bad[1]),
            bad_2: pct(self.bad[2]),
            bad_3: pct(self.bad[3]),
            bad_4: pct(self.bad[4]),
            d1_all: pct(self.d1),
            valid_pixels: self.valid_pixels,
        }
    }
}

/// Metric values; percentages in 0..100.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Mean absolute error (px).
    pub epe: f64,
    /// % with error > 0.5 px.
    pub bad_0_5: f64,
    /// % with error > 1 px.
    pub bad_1: f64,
    /// % with error > 2 px.
    pub bad_2: f64,
    /// % with error > 3 px.
    pub bad_3: f64,
    /// % with error > 4 px.
    pub bad_4: f64,
    /// % with error > 3 px and > 5 % of the ground truth.
    pub d1_all: f64,
    /// Number of pixels scored (for an average over images: the total).
    pub valid_pixels: u64,
}

impl Metrics {
    /// The values in the order of [`METRIC_NAMES`].
    pub fn values(&self) -> [f64; 7] {
        [self.epe, self.bad_0_5, self.bad_1, self.bad_2, self.bad_3, self.bad_4, self.d1_all]
    }

    /// The metrics of `values` in the order of [`METRIC_NAMES`] (the inverse of
    /// [`values`](Self::values)) over `valid_pixels` pixels.
    pub fn from_values(values: [f64; 7], valid_pixels: u64) -> Self {
        let [epe, bad_0_5, bad_1, bad_2, bad_3, bad_4, d1_all] = values;
        Self { epe, bad_0_5, bad_1, bad_2, bad_3, bad_4, d1_all, valid_pixels }
    }

    /// A metric by its name in [`METRIC_NAMES`].
    pub fn get(&self, name: &str) -> Option<f64> {
        METRIC_NAMES.iter().position(|n| *n == name).map(|i| self.values()[i])
    }

    /// The JSON object `{"epe": .., "bad-0.5": .., .., "d1-all": .., "valid_pixels": n}`
    /// (NaN becomes `null`).
    pub fn to_json(&self) -> serde_json::Value {
        let mut map = serde_json::Map::new();
        for (name, v) in METRIC_NAMES.iter().zip(self.values()) {
            map.insert(
                (*name).to_string(),
                serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, Into::into),
            );
        }
        map.insert("valid_pixels".into(), self.valid_pixels.into());
        serde_json::Value::Object(map)
    }

    /// The metrics of a [`to_json`](Self::to_json) object (`null` reads as NaN); `None` when a
    /// metric or `valid_pixels` is missing.
    pub fn from_json(value: &serde_json::Value) -> Option<Metrics> {
        let get = |name: &str| match &value[name] {
            serde_json::Value::Null if value.get(name).is_some() => Some(f64::NAN),
            v => v.as_f64(),
        };
        Some(Metrics {
            epe: get("epe")?,
            bad_0_5: get("bad-0.5")?,
            bad_1: get("bad-1")?,
            bad_2: get("bad-2")?,
            bad_3: get("bad-3")?,
            bad_4: get("bad-4")?,
            d1_all: get("d1-all")?,
            valid_pixels: value["valid_pixels"].as_u64()?,
        })
    }

    /// The mean of several metrics, each image weighing the same; `valid_pixels` is the total.
    /// Images without valid pixels are skipped.
    pub fn mean_of(items: &[Metrics]) -> Metrics {
        let used: Vec<&Metrics> = items.iter().filter(|m| m.valid_pixels > 0).collect();
        let k = used.len() as f64;
        let mut sum = [0f64; 7];
        for m in &used {
            for (s, v) in sum.iter_mut().zip(m.values()) {
                *s += v;
            }
        }
        let avg = sum.map(|s| if k > 0.0 { s / k } else { f64::NAN });
        Metrics {
            epe: avg[0],
            bad_0_5: avg[1],
            bad_1: avg[2],
            bad_2: avg[3],
            bad_3: avg[4],
            bad_4: avg[5],
            d1_all: avg[6],
            valid_pixels: used.iter().map(|m| m.valid_pixels).sum(),
        }
    }
}

/// The sums of `pred` against `gt` over valid pixels (see the module doc).
///
/// # Shapes
/// `pred`, `gt` and `mask` must all have the same width and height.
pub fn accumulate(
    pred: &DisparityMap,
    gt: &DisparityMap,
    mask: Option<&Mask>,
    opts: ValidOptions,
) -> Result<MetricSums> {
    if (pred.width, pred.height) != (gt.width, gt.height) {
        return Err(Error::Shape(format!(
            "prediction is {}x{}, ground truth {}x{}",
            pred.width, pred.height, gt.width, gt.height
        )));
    }
    if let Some(m) = mask
        && (m.width, m.height) != (gt.width, gt.height)
    {
        return Err(Error::Shape(format!("mask is {}x{}, ground truth {}x{}", m.width, m.height, gt.width, gt.height)));
    }
    let max = opts.max_disp.unwrap_or(f32::INFINITY);
    let mut sums = MetricSums::default();
    for i in 0..gt.data.len() {
        let g = gt.data[i];
        if g.is_finite() && g > 0.0 && g < max && mask.is_none_or(|m| m.data[i]) {
            sums.add(pred.data[i], g);
        }
    }
    Ok(sums)
}

/// The metrics of `pred` against `gt` over valid pixels (see the module doc).
pub fn evaluate(pred: &DisparityMap, gt: &DisparityMap, mask: Option<&Mask>, opts: ValidOptions) -> Result<Metrics> {
    Ok(accumulate(pred, gt, mask, opts)?.metrics())
}
