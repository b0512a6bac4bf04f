//! DrivingStereo's weather subsets, each selectable on its own.
//!
//! The layout is the one of the official "different weathers" download, one folder per weather
//! under `root`:
//!
//! ```text
//! root/
//!   sunny/
//!     left-image-full-size/<sequence>_<time>.png      (or left-image-half-size/*.jpg)
//!     right-image-full-size/<same file name>
//!     disparity-map-full-size/<same stem>.png         16-bit PNG, value / 256, 0 = unknown
//!   cloudy/  foggy/  rainy/                           (the same)
//! ```
//!
//! The full-size folders are used when present, else the half-size ones. Each sample is named
//! `<weather>/<stem>` and grouped by its weather, so a table of several weathers aggregates each
//! on its own (the paper reports every weather separately). Valid ground truth: `> 0`.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

use super::sceneflow::walk;
use super::{FileDataset, SampleFiles, ValidRule};

/// A DrivingStereo weather subset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DrivingStereoWeather {
    /// `sunny/`.
    Sunny,
    /// `cloudy/`.
    Cloudy,
    /// `foggy/`.
    Foggy,
    /// `rainy/`.
    Rainy,
}

impl DrivingStereoWeather {
    /// The four weathers, in the paper's column order.
    pub const ALL: [Self; 4] = [Self::Sunny, Self::Cloudy, Self::Foggy, Self::Rainy];

    /// The weather's name: its folder, its TOML and command-line value, its group label.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sunny => "sunny",
            Self::Cloudy => "cloudy",
            Self::Foggy => "foggy",
            Self::Rainy => "rainy",
        }
    }
}

impl fmt::Display for DrivingStereoWeather {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DrivingStereoWeather {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL.into_iter().find(|w| w.name() == s).ok_or_else(|| {
            Error::config(
                "weather",
                format!("unknown DrivingStereo weather '{s}' (expected sunny, cloudy, foggy or rainy)"),
            )
        })
    }
}

/// Lists the weather subsets `weathers` of DrivingStereo under `root` (the layout of the module
/// doc); an empty `weathers` lists every weather folder present. A chosen weather without its
/// folder is an error naming the folder, and so is a `root` with no weather folder at all.
pub fn drivingstereo(root: &Path, weathers: &[DrivingStereoWeather]) -> Result<FileDataset> {
    let chosen: Vec<DrivingStereoWeather> = if weathers.is_empty() {
        DrivingStereoWeather::ALL.into_iter().filter(|w| root.join(w.name()).is_dir()).collect()
    } else {
        weathers.to_vec()
    };
    if chosen.is_empty() {
        let message = if size_of(root).is_some() {
            "one DrivingStereo weather's folder: give the folder that holds sunny/, cloudy/, foggy/ and rainy/"
        } else {
            "no DrivingStereo weather folder (sunny/, cloudy/, foggy/, rainy/) in this folder"
        };
        return Err(Error::format(root, message));
    }
    let mut files = Vec::new();
    for weather in chosen {
        let dir = root.join(weather.name());
        if !dir.is_dir() {
            return Err(Error::format(&dir, "DrivingStereo weather folder not found"));
        }
        let size = size_of(&dir).ok_or_else(|| {
            Error::format(&dir, "holds neither left-image-full-size/ nor left-image-half-size/ (DrivingStereo)")
        })?;
        files.extend(weather_files(&dir, weather, size)?);
    }
    Ok(FileDataset { files, rule: ValidRule::Positive })
}

/// `full-size` or `half-size`, whichever left-image folder `dir` holds (full first).
fn size_of(dir: &Path) -> Option<&'static str> {
    ["full-size", "half-size"].into_iter().find(|s| dir.join(format!("left-image-{s}")).is_dir())
}

fn weather_files(dir: &Path, weather: DrivingStereoWeather, size: &str) -> Result<Vec<SampleFiles>> {
    let mut lefts: Vec<PathBuf> = Vec::new();
    walk(&dir.join(format!("left-image-{size}")), &mut lefts)?;
    let is_image = |p: &PathBuf| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
    };
    let disparity_dir = dir.join(format!("disparity-map-{size}"));
    Ok(lefts
        .into_iter()
        .filter(is_image)
        .map(|left| {
            let file = left.file_name().map(|n| n.to_os_string()).unwrap_or_default();
            let stem = left.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let disparity = disparity_dir.join(format!("{stem}.png"));
            SampleFiles {
                name: format!("{weather}/{stem}"),
                group: Some(weather.name().to_string()),
                right: dir.join(format!("right-image-{size}")).join(file),
                disparity: disparity.is_file().then_some(disparity),
                left,
                nonoccluded: None,
            }
        })
        .collect())
}
