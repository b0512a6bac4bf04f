//! Data for dgstereo: image and disparity formats, dataset layouts, synthetic stereo and
//! RAFT-Stereo's augmentation, in pure Rust (no tensor library) so it builds fast.
//!
//! Images are [`RgbImage`] (planar `CHW` `f32` in 0..255, the model's input layout); disparity
//! is a row-major [`DisparityMap`] of the left view with non-finite values meaning "unknown";
//! validity is a boolean [`Mask`]. Each file format has its own module with a reader and a writer
//! that name the file in every error ([`dgstereo_core::Error`]). Dataset layouts
//! ([`datasets`]) only list files ([`SampleFiles`]); a [`FileDataset`] reads them on demand and a
//! [`PrefetchLoader`] reads ahead on rayon's pool; [`headers`] reads a sample's sizes from its
//! files' headers, for checks before hours of training (reading a sample checks the same sizes).
//! The [`synthetic`] generator renders exact stereo scenes by ray casting disparity-linear
//! surfaces, and [`mod@augment`] reproduces the dense FlowAugmentor, resizing disparity both
//! bilinearly and by nearest neighbour, and the sparse one ([`augment_sparse`]) that moves the
//! valid points of real ground truth instead. [`visualize`] draws disparity maps as pictures (the
//! turbo colour map with a legend, error images, panels side by side).
#![deny(missing_docs)]

pub mod augment;
pub mod datasets;
pub mod disparity_io;
pub mod headers;
pub mod image;
pub mod kitti_png;
pub mod loader;
pub mod npy;
pub mod pfm;
pub mod resize;
pub mod synthetic;
pub mod text;
pub mod visualize;

pub use augment::{AugmentConfig, AugmentedSample, augment, augment_sparse};
pub use datasets::{Dataset, FileDataset, Sample, SampleFiles, SyntheticDataset, ValidRule};
pub use disparity_io::{DisparityFormat, read_disparity, write_disparity};
pub use image::{DisparityMap, Mask, RgbImage, load_mask, load_rgb, save_mask, save_rgb};
pub use loader::PrefetchLoader;
pub use synthetic::{SyntheticConfig, SyntheticSample, SyntheticScene};
