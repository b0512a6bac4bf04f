//! Benchmark protocols: which pixels count and how per-image results are aggregated, as
//! RAFT-Stereo's `evaluate_stereo.py` does.
//!
//! In every protocol `epe` is the mean of the per-image EPEs (RAFT averages EPE over images).
//! The bad-pixel rates are aggregated per protocol, see [`Protocol`]. Pixels whose ground truth
//! is not finite or not `> 0` never count (for the dense sets, a ground truth of exactly 0 is
//! practically absent, so this matches RAFT's rules).

use serde::{Deserialize, Serialize};

use crate::metrics::{MetricSums, Metrics, ValidOptions};

/// How bad-pixel percentages are combined over images.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Aggregation {
    /// Sum of bad pixels over the sum of valid pixels of all images.
    Pooled,
    /// Mean of the per-image percentages.
    MeanPerImage,
}

/// A benchmark's evaluation protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Protocol {
    /// KITTI 2012/2015 training: ground truth `disp_occ` (/256), valid where `gt > 0`; headline
    /// **bad-3 pooled over all valid pixels** (RAFT's "D1" has no 5 % rule; `d1-all`, also
    /// pooled, is KITTI's official rule with it).
    Kitti,
    /// Middlebury (MiddEval3 F/H/Q training): valid where ground truth is finite (inf = unknown;
    /// the nocc mask is not used); headline **bad-2, mean of per-image percentages**.
    Middlebury,
    /// ETH3D two-view training: valid where ground truth is finite and `< 512` (occluded pixels
    /// included); headline **bad-1, mean of per-image percentages**.
    Eth3d,
    /// FlyingThings3D finalpass test: valid where `|gt| < 192`; headline **bad-1 pooled**.
    FlyingThings,
    /// DrivingStereo: ground truth /256, valid where `gt > 0`; headline **EPE and bad-3, each
    /// the mean over the images of one weather subset** (rows grouped by weather).
    DrivingStereo,
    /// No benchmark: all valid pixels, bad rates pooled, headline EPE.
    Generic,
}

impl Protocol {
    /// How bad-pixel rates are aggregated.
    pub fn aggregation(self) -> Aggregation {
        match self {
            Protocol::Kitti | Protocol::FlyingThings | Protocol::Generic => Aggregation::Pooled,
            Protocol::Middlebury | Protocol::Eth3d | Protocol::DrivingStereo => Aggregation::MeanPerImage,
        }
    }

    /// The validity options (beyond finite and `> 0`).
    pub fn valid_options(self) -> ValidOptions {
        match self {
            Protocol::Eth3d => ValidOptions { max_disp: Some(512.0) },
            Protocol::FlyingThings => ValidOptions { max_disp: Some(192.0) },
            _ => ValidOptions::default(),
        }
    }

    /// The headline metric names.
    pub fn headline(self) -> &'static [&'static str] {
        match self {
            Protocol::Kitti => &["bad-3", "d1-all"],
            Protocol::Middlebury => &["bad-2"],
            Protocol::Eth3d | Protocol::FlyingThings => &["bad-1"],
            Protocol::DrivingStereo => &["epe", "bad-3"],
            Protocol::Generic => &["epe"],
        }
    }

    /// A lower-case name (`kitti`, `middlebury`, `eth3d`, `flyingthings`, `drivingstereo`,
    /// `generic`).
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Kitti => "kitti",
            Protocol::Middlebury => "middlebury",
            Protocol::Eth3d => "eth3d",
            Protocol::FlyingThings => "flyingthings",
            Protocol::DrivingStereo => "drivingstereo",
            Protocol::Generic => "generic",
        }
    }

    /// Aggregates per-image sums: `epe` is the mean of per-image EPEs, the bad rates follow
    /// [`Protocol::aggregation`], `valid_pixels` is the total. Images without valid pixels are
    /// skipped.
    pub fn aggregate(self, images: &[MetricSums]) -> Metrics {
        let per_image: Vec<Metrics> = images.iter().filter(|s| s.valid_pixels > 0).map(|s| s.metrics()).collect();
        let mean = Metrics::mean_of(&per_image);
        match self.aggregation() {
            Aggregation::MeanPerImage => mean,
            Aggregation::Pooled => {
                let mut pooled = MetricSums::default();
                for s in images {
                    pooled.merge(s);
                }
                Metrics { epe: mean.epe, ..pooled.metrics() }
            }
        }
    }
}
