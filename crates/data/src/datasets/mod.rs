//! Datasets: layouts list the files of each sample ([`SampleFiles`]); a [`FileDataset`] reads
//! them on demand into [`Sample`]s, applying the dataset's validity rule.
//!
//! Layout functions ([`middlebury2014`], [`middeval3`], [`eth3d`], [`sceneflow`],
//! [`flyingthings_test`], [`drivingstereo`], [`kitti`], [`folder_pairs`]) only walk folders, so
//! listing is cheap and reading can happen on worker threads ([`crate::loader`]).
//! [`SyntheticDataset`] renders samples instead of reading. Which files of a plain folder are
//! pairs is one rule, [`pair_finder`], shared with the pairs a user names ([`pair_list`]: folders, lists
//! of files or patterns, list files, and the names of their outputs), which `dgstereo infer` reads.

mod drivingstereo;
mod flyingthings_subset;
mod layouts;
mod middeval3;
mod numpy_permutation;
pub mod pair_finder;
pub mod pair_list;
mod sceneflow;

pub use drivingstereo::{DrivingStereoWeather, drivingstereo};
pub use flyingthings_subset::{
    FlyingThingsTestSubset, RAFT_STEREO_SUBSET_SEED, RAFT_STEREO_SUBSET_SIZE, flyingthings_test,
};
pub use layouts::{KittiVersion, eth3d, folder_pairs, kitti, middlebury2014};
pub use middeval3::{MiddleburySplit, middeval3, middeval3_splits_in};
pub use numpy_permutation::numpy_permutation;
pub use sceneflow::{SceneFlowPass, SceneFlowSubset, sceneflow};

use std::path::{Path, PathBuf};

use dgstereo_core::Result;

use crate::headers::{disparity_size, image_size, size_mismatch};

use crate::image::{DisparityMap, Mask, RgbImage, load_mask, load_rgb};
use crate::read_disparity;
use crate::synthetic::{SyntheticConfig, generate};

/// Which ground-truth values are valid (always also finite).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ValidRule {
    /// Finite and `> 0` (KITTI, DrivingStereo: 0 marks no ground truth).
    Positive,
    /// Finite (Middlebury: inf marks no ground truth).
    Finite,
    /// Finite and `|d| <` the bound (SceneFlow and ETH3D: 512).
    Below(f32),
}

impl ValidRule {
    /// Whether a ground-truth value is valid.
    pub fn accepts(self, d: f32) -> bool {
        d.is_finite()
            && match self {
                ValidRule::Positive => d > 0.0,
                ValidRule::Finite => true,
                ValidRule::Below(m) => d.abs() < m,
            }
    }

    /// The valid mask of a disparity map.
    pub fn mask(self, d: &DisparityMap) -> Mask {
        Mask { width: d.width, height: d.height, data: d.data.iter().map(|v| self.accepts(*v)).collect() }
    }
}

/// The files of one sample.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleFiles {
    /// A name unique in the dataset (relative path or scene name).
    pub name: String,
    /// Group label (weather, scene type), if any.
    pub group: Option<String>,
    /// Left image.
    pub left: PathBuf,
    /// Right image.
    pub right: PathBuf,
    /// Left disparity (`.pfm`, KITTI `.png`, `.npy`), if there is ground truth.
    pub disparity: Option<PathBuf>,
    /// Non-occlusion mask picture (non-zero = visible in both views), if any.
    pub nonoccluded: Option<PathBuf>,
}

/// One loaded sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Name.
    pub name: String,
    /// Group label.
    pub group: Option<String>,
    /// Left view.
    pub left: RgbImage,
    /// Right view.
    pub right: RgbImage,
    /// Left disparity, if known.
    pub disparity: Option<DisparityMap>,
    /// Valid ground truth (by the dataset's rule), if there is ground truth.
    pub valid: Option<Mask>,
    /// Visible in both views, if the dataset says.
    pub nonoccluded: Option<Mask>,
}

/// A random-access collection of samples, shareable across threads.
pub trait Dataset: Send + Sync {
    /// Number of samples.
    fn len(&self) -> usize;
    /// Whether there are no samples.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Loads sample `index`.
    fn get(&self, index: usize) -> Result<Sample>;
}

/// A dataset of files with a validity rule.
#[derive(Clone, Debug, PartialEq)]
pub struct FileDataset {
    /// The samples' files.
    pub files: Vec<SampleFiles>,
    /// Which ground-truth values are valid.
    pub rule: ValidRule,
}

impl SampleFiles {
    /// Checks the sample's files by their headers, without decoding them
    /// ([`crate::headers`]): both views of one size, the ground truth complete and of the left
    /// view's size, the non-occlusion mask of that size too. Returns the left view's
    /// `(width, height)`.
    ///
    /// # Errors
    /// A file that cannot be opened, a header that cannot be read, a disparity file cut short,
    /// or a file whose size is not the left view's (naming both files).
    pub fn check_headers(&self) -> Result<(usize, usize)> {
        let size = image_size(&self.left)?;
        self.check_size(&self.right, "the right view", image_size(&self.right)?, size)?;
        if let Some(d) = &self.disparity {
            self.check_size(d, "the ground truth", disparity_size(d)?, size)?;
        }
        if let Some(m) = &self.nonoccluded {
            self.check_size(m, "the non-occlusion mask", image_size(m)?, size)?;
        }
        Ok(size)
    }

    fn check_size(&self, path: &Path, what: &str, found: (usize, usize), left: (usize, usize)) -> Result<()> {
        if found == left { Ok(()) } else { Err(size_mismatch(path, what, found, &self.left, left)) }
    }
}

impl FileDataset {
    /// Reads one sample's files.
    ///
    /// # Errors
    /// A file that cannot be read, and a file whose size is not the left view's (naming both
    /// files): the views, the ground truth and the masks of a sample are of one size.
    pub fn load(files: &SampleFiles, rule: ValidRule) -> Result<Sample> {
        let left = load_rgb(&files.left)?;
        let size = (left.width, left.height);
        let right = load_rgb(&files.right)?;
        files.check_size(&files.right, "the right view", (right.width, right.height), size)?;
        let disparity = files.disparity.as_ref().map(read_disparity).transpose()?;
        if let (Some(path), Some(d)) = (&files.disparity, &disparity) {
            files.check_size(path, "the ground truth", (d.width, d.height), size)?;
        }
        let valid = disparity.as_ref().map(|d| rule.mask(d));
        let nonoccluded = files.nonoccluded.as_ref().map(load_mask).transpose()?;
        if let (Some(path), Some(m)) = (&files.nonoccluded, &nonoccluded) {
            files.check_size(path, "the non-occlusion mask", (m.width, m.height), size)?;
        }
        Ok(Sample { name: files.name.clone(), group: files.group.clone(), left, right, disparity, valid, nonoccluded })
    }
}

impl Dataset for FileDataset {
    fn len(&self) -> usize {
        self.files.len()
    }

    fn get(&self, index: usize) -> Result<Sample> {
        let f = self.files.get(index).ok_or_else(|| {
            dgstereo_core::Error::sample(
                format!("#{index}"),
                format!("out of range (a data set of {})", self.files.len()),
            )
        })?;
        Self::load(f, self.rule)
    }
}

/// Synthetic samples: sample `i` is the scene of seed `seed + i`.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticDataset {
    /// Generator settings.
    pub config: SyntheticConfig,
    /// Seed of sample 0.
    pub seed: u64,
    /// Number of samples.
    pub len: usize,
}

impl Dataset for SyntheticDataset {
    fn len(&self) -> usize {
        self.len
    }

    fn get(&self, index: usize) -> Result<Sample> {
        let s = generate(&self.config, self.seed.wrapping_add(index as u64));
        let nonoccluded = Mask { data: s.occlusion.data.iter().map(|o| !o).collect(), ..s.occlusion };
        Ok(Sample {
            name: format!("synthetic/{}", self.seed.wrapping_add(index as u64)),
            group: None,
            left: s.left,
            right: s.right,
            disparity: Some(s.disparity),
            valid: Some(s.valid),
            nonoccluded: Some(nonoccluded),
        })
    }
}
