//! [`TrainingDataConfig`]: where training pairs come from, the `[data]` table.

use dgstereo_core::{Problem, Result};
use serde::{Deserialize, Serialize};

use super::source::DataSource;
use super::validation_set::ValidationConfig;

/// Where training pairs come from (the `[data]` table).
///
/// ```toml
/// [data]
/// augment = true
/// [[data.sources]]
/// kind = "synthetic"     # or "sceneflow", "middlebury", "eth3d", "kitti", "folder"
/// weight = 1.0           # share of the batch elements drawn from this source
/// width = 640
/// height = 384
/// textures = "smooth"    # or "rich": dead-leaves shapes, flat and low-contrast surfaces, shading
/// [data.validation]
/// count = 8              # held-out synthetic pairs (scene seeds 2^40 + i; training draws other seeds)
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainingDataConfig {
    /// The training sources, mixed by their weights.
    pub sources: Vec<DataSource>,
    /// RAFT-Stereo's augmentation (colour, eraser, scale, crop); off: a random crop only.
    pub augment: bool,
    /// `log2` range of the augmentation's scale (`spatial_scale`).
    pub spatial_scale: [f64; 2],
    /// Saturation range of the colour jitter (`saturation_range`).
    pub saturation_range: [f32; 2],
    /// The validation set.
    pub validation: ValidationConfig,
}

impl Default for TrainingDataConfig {
    fn default() -> Self {
        Self {
            sources: vec![DataSource::default()],
            augment: true,
            spatial_scale: [-0.2, 0.4],
            saturation_range: [0.0, 1.4],
            validation: ValidationConfig::default(),
        }
    }
}

impl TrainingDataConfig {
    /// Checks that the files the keys name are there: the photo folders of the synthetic sources
    /// and of the validation set. [`validate`](Self::validate) reads no files, so an experiment
    /// file checks on a machine that has not fetched the data; this runs where the data is opened.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] naming the key as an experiment file writes it
    /// (`data.sources[0].photos.dir`).
    pub fn check_files(&self) -> Result<()> {
        for (i, s) in self.sources.iter().enumerate() {
            if let DataSource::Synthetic { scenes, .. } = s {
                scenes.check_files().map_err(|e| e.within(&format!("data.sources[{i}]")))?;
            }
        }
        self.validation.scenes.check_files().map_err(|e| e.within("data.validation"))
    }

    /// Everything wrong with the values without reading files, keys relative to the `[data]`
    /// table (`sources[0].weight`, `validation.min_disparity`).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        if self.sources.is_empty() {
            problems.push(Problem::new("sources", "is empty: give at least one training source"));
        }
        for (i, s) in self.sources.iter().enumerate() {
            problems.extend(s.problems().into_iter().map(|p| p.within(&format!("sources[{i}]"))));
        }
        problems.extend(self.validation.problems().into_iter().map(|p| p.within("validation")));
        if !self.sources.is_empty() && self.sources.iter().map(DataSource::weight).sum::<f64>() <= 0.0 {
            problems.push(Problem::new("sources", "the weights sum to 0"));
        }
        if self.spatial_scale[0] > self.spatial_scale[1] {
            problems.push(Problem::new("spatial_scale", format!("{:?}: expected [min, max]", self.spatial_scale)));
        }
        problems
    }

    /// Checks the values without reading files.
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] with the first of [`problems`](Self::problems), its key
    /// as an experiment file writes it (`data.sources[0].weight`).
    pub fn validate(&self) -> Result<()> {
        Problem::first(self.problems()).map_err(|e| e.within("data"))
    }
}
