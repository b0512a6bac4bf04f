//! Benchmarks by name: a data set layout, its folder, and the protocol that scores it.
//!
//! [`DatasetKind`] ties each layout reader of the data crate to its [`Protocol`]; it is what
//! `dgstereo eval --dataset` takes and what an experiment's `[[benchmarks]]` entries name, so the
//! ablation runner and the eval command score a data set the same way.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use dgstereo_core::{Error, Problem, Result};
use dgstereo_data::FileDataset;
use dgstereo_data::datasets::{
    DrivingStereoWeather, FlyingThingsTestSubset, KittiVersion, MiddleburySplit, SceneFlowPass, SceneFlowSubset,
    drivingstereo, eth3d, flyingthings_test, folder_pairs, kitti, middeval3, middeval3_splits_in, middlebury2014,
    sceneflow,
};
use serde::{Deserialize, Serialize};

use crate::Protocol;

/// A data set layout with ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DatasetKind {
    /// Middlebury: with a split (Q, H, F), the MiddEval3 folder; without one, a folder of scene
    /// folders with im0.png, im1.png, disp0GT.pfm (a MiddEval3 split folder, Middlebury 2014).
    Middlebury,
    /// ETH3D two-view (two_view_training + two_view_training_gt).
    Eth3d,
    /// KITTI 2012 training folder (colored_0, colored_1, disp_occ).
    Kitti2012,
    /// KITTI 2015 training folder (image_2, image_3, disp_occ_0).
    Kitti2015,
    /// SceneFlow FlyingThings3D finalpass TEST (all pairs, or RAFT-Stereo's 400 with a subset).
    Sceneflow,
    /// DrivingStereo weather subsets (sunny, cloudy, foggy, rainy; all present, or one).
    Drivingstereo,
    /// A folder of pairs (`*left*`/`*right*` or im0/im1) with `*disp*` or disp0GT ground truth,
    /// e.g. the bundled Cones pair in assets/cones.
    Folder,
}

impl DatasetKind {
    /// Every kind, in the order of the documentation.
    pub const ALL: [Self; 7] = [
        Self::Middlebury,
        Self::Eth3d,
        Self::Kitti2012,
        Self::Kitti2015,
        Self::Sceneflow,
        Self::Drivingstereo,
        Self::Folder,
    ];

    /// The kind's name (as in TOML and on the command line).
    pub fn name(self) -> &'static str {
        match self {
            Self::Middlebury => "middlebury",
            Self::Eth3d => "eth3d",
            Self::Kitti2012 => "kitti2012",
            Self::Kitti2015 => "kitti2015",
            Self::Sceneflow => "sceneflow",
            Self::Drivingstereo => "drivingstereo",
            Self::Folder => "folder",
        }
    }

    /// Lists the samples of the data set in `root`, without a split, weather or subset (see
    /// [`BenchmarkConfig::load`] for those).
    pub fn load(self, root: &Path) -> Result<FileDataset> {
        match self {
            Self::Middlebury => middlebury2014(root),
            Self::Eth3d => eth3d(root),
            Self::Kitti2012 => kitti(root, KittiVersion::K2012),
            Self::Kitti2015 => kitti(root, KittiVersion::K2015),
            Self::Sceneflow => sceneflow(root, SceneFlowSubset::FlyingThingsTest, SceneFlowPass::Final),
            Self::Drivingstereo => drivingstereo(root, &[]),
            Self::Folder => folder_pairs(root),
        }
    }

    /// The protocol that scores this data set.
    pub fn protocol(self) -> Protocol {
        match self {
            Self::Middlebury => Protocol::Middlebury,
            Self::Eth3d => Protocol::Eth3d,
            Self::Kitti2012 | Self::Kitti2015 => Protocol::Kitti,
            Self::Sceneflow => Protocol::FlyingThings,
            Self::Drivingstereo => Protocol::DrivingStereo,
            Self::Folder => Protocol::Generic,
        }
    }
}

impl fmt::Display for DatasetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DatasetKind {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|k| k.name()).collect();
            Error::config("dataset", format!("unknown data set '{s}' (expected one of: {})", names.join(", ")))
        })
    }
}

/// A benchmark of an experiment (`[[benchmarks]]`): which data set, where, and how to run on it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BenchmarkConfig {
    /// Column label in tables (default: the data set kind's name).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The layout.
    pub dataset: DatasetKind,
    /// The data set's folder (relative paths: to the working directory).
    pub root: PathBuf,
    /// Update iterations (32, the papers' evaluation setting).
    #[serde(default = "default_iters")]
    pub iters: usize,
    /// Score only the first N samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limit: Option<usize>,
    /// Downscale pairs whose longer side exceeds this many pixels before the network (the
    /// disparity is brought back to the full size and scored there): for models trained on a
    /// smaller disparity range, such as the CPU smoke runs. Not the benchmark's protocol.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_size: Option<usize>,
    /// Middlebury only: the MiddEval3 split (`"Q"`, `"H"`, `"F"`); `root` is then the MiddEval3
    /// folder (see [`middeval3`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub split: Option<MiddleburySplit>,
    /// DrivingStereo only: the one weather to score (`"sunny"`, `"cloudy"`, `"foggy"`,
    /// `"rainy"`); without it every weather folder present, each a group of the table.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weather: Option<DrivingStereoWeather>,
    /// SceneFlow only: which FlyingThings3D TEST pairs (`"all"`, the default, or
    /// `"raft-stereo-400"`, RAFT-Stereo's validation subset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub subset: Option<FlyingThingsTestSubset>,
}

fn default_iters() -> usize {
    32
}

impl BenchmarkConfig {
    /// The label of the benchmark's columns.
    pub fn label(&self) -> &str {
        self.name.as_deref().unwrap_or(self.dataset.name())
    }

    /// The benchmark's settings in words, for tables and messages: its data set and folder, its
    /// split, weather or subset, iterations, how many samples and the size limit
    /// (`folder at /data/cones, 2 iterations, first 5 samples, longer side at most 96 px`).
    pub fn settings(&self) -> String {
        let mut parts = vec![format!("{} at {}", self.dataset, self.root.display())];
        parts.extend(self.split.map(|s| format!("split {s}")));
        parts.extend(self.weather.map(|w| format!("weather {w}")));
        parts.extend(self.subset.map(|s| format!("subset {s}")));
        parts.push(format!("{} iteration{}", self.iters, if self.iters == 1 { "" } else { "s" }));
        parts.extend(self.limit.map(|n| format!("first {n} samples")));
        parts.extend(self.max_size.map(|m| format!("longer side at most {m} px")));
        parts.join(", ")
    }

    /// The metrics the ablation table shows for it: EPE and the protocol's headline (bad-2 and
    /// bad-3 for a plain folder, whose protocol has no headline rate).
    pub fn table_metrics(&self) -> Vec<&'static str> {
        let mut m = vec!["epe"];
        match self.dataset.protocol() {
            Protocol::Generic => m.extend(["bad-2", "bad-3"]),
            p => m.extend(p.headline().iter().filter(|h| **h != "epe")),
        }
        m
    }

    /// A benchmark of `dataset` in `root` with the default settings (32 iterations, every
    /// sample, no split, weather or subset).
    pub fn new(dataset: DatasetKind, root: impl Into<PathBuf>) -> Self {
        Self {
            name: None,
            dataset,
            root: root.into(),
            iters: default_iters(),
            limit: None,
            max_size: None,
            split: None,
            weather: None,
            subset: None,
        }
    }

    /// The options set for another data set than the one they belong to, as `(key, message)`:
    /// `split` belongs to middlebury, `weather` to drivingstereo, `subset` to sceneflow.
    pub fn option_problems(&self) -> Vec<(&'static str, String)> {
        let set = [
            ("split", self.split.is_some(), DatasetKind::Middlebury),
            ("weather", self.weather.is_some(), DatasetKind::Drivingstereo),
            ("subset", self.subset.is_some(), DatasetKind::Sceneflow),
        ];
        set.into_iter()
            .filter(|(_, given, owner)| *given && *owner != self.dataset)
            .map(|(key, _, owner)| (key, format!("only a {owner} benchmark has a {key}; this one is {}", self.dataset)))
            .collect()
    }

    /// Everything wrong with the benchmark's values, keys relative to its table: `iters` at
    /// least 1, and the [options of another data set](Self::option_problems).
    pub fn problems(&self) -> Vec<Problem> {
        let iters = (self.iters == 0).then(|| Problem::new("iters", "must be at least 1"));
        iters
            .into_iter()
            .chain(self.option_problems().into_iter().map(|(key, reason)| Problem::new(key, reason)))
            .collect()
    }

    /// Lists the benchmark's samples: the data set in `root` with the split, weather or subset.
    ///
    /// # Errors
    /// An option that belongs to another data set (naming the key), a MiddEval3 folder given
    /// without a split, and the layout reader's errors (naming the folder).
    pub fn load(&self) -> Result<FileDataset> {
        if let Some((key, message)) = self.option_problems().into_iter().next() {
            return Err(Error::config(key, format!("{message} (benchmark '{}')", self.label())));
        }
        match self.dataset {
            DatasetKind::Middlebury => match self.split {
                Some(split) => middeval3(&self.root, split),
                None => {
                    let splits = middeval3_splits_in(&self.root);
                    if !splits.is_empty() {
                        let names: Vec<&str> = splits.iter().map(|s| s.name()).collect();
                        return Err(Error::config(
                            "split",
                            format!(
                                "root {} is a MiddEval3 folder: set split to one of {} (benchmark '{}')",
                                self.root.display(),
                                names.join(", "),
                                self.label()
                            ),
                        ));
                    }
                    middlebury2014(&self.root)
                }
            },
            DatasetKind::Drivingstereo => drivingstereo(&self.root, self.weather.as_slice()),
            DatasetKind::Sceneflow => {
                flyingthings_test(&self.root, SceneFlowPass::Final, self.subset.unwrap_or_default())
            }
            other => other.load(&self.root),
        }
    }

    /// Lists the samples to score (the first `limit`), with a clear error when the folder is
    /// missing or holds no sample with ground truth.
    pub fn dataset(&self) -> Result<(FileDataset, Vec<usize>)> {
        let shown = std::path::absolute(&self.root).unwrap_or_else(|_| self.root.clone());
        if !self.root.is_dir() {
            return Err(Error::config(
                "root",
                format!("{} is not a folder (benchmark '{}')", shown.display(), self.label()),
            ));
        }
        let dataset = self.load()?;
        if dataset.files.is_empty() {
            return Err(Error::config(
                "root",
                format!(
                    "{} holds no pair of the {} layout (benchmark '{}')",
                    shown.display(),
                    self.dataset,
                    self.label()
                ),
            ));
        }
        if !dataset.files.iter().any(|f| f.disparity.is_some()) {
            return Err(Error::config(
                "root",
                format!("no sample in {} has ground truth disparity (benchmark '{}')", shown.display(), self.label()),
            ));
        }
        let n = self.limit.unwrap_or(usize::MAX).min(dataset.files.len());
        Ok((dataset, (0..n).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_through_str_and_toml() {
        for k in DatasetKind::ALL {
            assert_eq!(k.name().parse::<DatasetKind>().unwrap(), k);
            let b: BenchmarkConfig = toml::from_str(&format!("dataset = '{k}'\nroot = 'x'")).unwrap();
            assert_eq!(b.dataset, k);
            assert_eq!(b.iters, 32);
        }
        let e = "kitti".parse::<DatasetKind>().unwrap_err().to_string();
        assert!(e.contains("kitti2015"), "{e}");
    }

    #[test]
    fn unknown_keys_and_missing_roots_are_errors() {
        assert!(toml::from_str::<BenchmarkConfig>("dataset = 'folder'\nroot = 'x'\niter = 3").is_err());
        let b: BenchmarkConfig = toml::from_str("dataset = 'folder'\nroot = '/nonexistent/cones'").unwrap();
        let e = b.dataset().unwrap_err().to_string();
        assert!(e.contains("/nonexistent/cones") && e.contains("folder"), "{e}");
    }

    #[test]
    fn table_metrics_follow_the_protocol() {
        let b = |d| BenchmarkConfig::new(d, PathBuf::new());
        assert_eq!(b(DatasetKind::Middlebury).table_metrics(), vec!["epe", "bad-2"]);
        assert_eq!(b(DatasetKind::Kitti2015).table_metrics()[0], "epe");
        assert_eq!(b(DatasetKind::Folder).table_metrics(), vec!["epe", "bad-2", "bad-3"]);
        assert_eq!(b(DatasetKind::Folder).label(), "folder");
    }

    #[test]
    fn settings_say_what_is_scored_and_how() {
        let mut b = BenchmarkConfig::new(DatasetKind::Drivingstereo, "/data/ds");
        assert_eq!(b.settings(), "drivingstereo at /data/ds, 32 iterations");
        b.weather = Some(DrivingStereoWeather::Foggy);
        b.iters = 1;
        b.limit = Some(5);
        b.max_size = Some(96);
        assert_eq!(
            b.settings(),
            "drivingstereo at /data/ds, weather foggy, 1 iteration, first 5 samples, longer side at most 96 px"
        );
    }
}
