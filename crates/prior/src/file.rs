//! The `file` prior provider: priors computed elsewhere, one file per view and pair.
//!
//! For a pair named `name` ([`PriorInput::names`]) the left prior is the file
//! `<dir>/<left pattern>` with `{name}` replaced (default `{name}_left`), likewise the right; when
//! the pattern has no extension, `.npy`, `.pfm` and `.png` are tried in that order. A map whose
//! size differs from the images' is resized bilinearly with `align_corners=True`, as Depth
//! Anything's own output is. A missing or unreadable file is an error naming it.

use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_core::{Error, Result};
use dgstereo_kernels::resize_bilinear;

use crate::formats::{DepthMap, EXTENSIONS, read_depth_map};
use crate::{DepthPrior, PriorInput, PriorProvider};

/// The default file-name pattern of left priors.
pub const DEFAULT_LEFT_PATTERN: &str = "{name}_left";
/// The default file-name pattern of right priors.
pub const DEFAULT_RIGHT_PATTERN: &str = "{name}_right";

/// Reads precomputed priors from a folder.
#[derive(Debug, Clone)]
pub struct FilePrior {
    dir: PathBuf,
    left_pattern: String,
    right_pattern: String,
}

impl FilePrior {
    /// A provider reading `dir/<pattern>` files; `{name}` in a pattern is the pair's name.
    pub fn new(dir: impl Into<PathBuf>, left_pattern: impl Into<String>, right_pattern: impl Into<String>) -> Self {
        Self { dir: dir.into(), left_pattern: left_pattern.into(), right_pattern: right_pattern.into() }
    }

    /// The file holding the prior of pair `name` for `pattern`.
    pub fn locate(&self, pattern: &str, name: &str) -> Result<PathBuf> {
        let stem = self.dir.join(pattern.replace("{name}", name));
        let has_known_extension = stem
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        if has_known_extension {
            return if stem.is_file() { Ok(stem) } else { Err(not_found(&stem)) };
        }
        EXTENSIONS
            .iter()
            .map(|ext| PathBuf::from(format!("{}.{ext}", stem.display())))
            .find(|p| p.is_file())
            .ok_or_else(|| not_found(&PathBuf::from(format!("{}.{{npy,pfm,png}}", stem.display()))))
    }

    fn load_view(&self, pattern: &str, names: &[String], size: [usize; 2], device: &Device) -> Result<Tensor<4>> {
        let maps = names
            .iter()
            .map(|name| {
                let path = self.locate(pattern, name)?;
                let map = read_depth_map(&path)?;
                if let Some(bad) = map.values.iter().find(|v| !v.is_finite()) {
                    return Err(Error::format(&path, format!("prior holds a non-finite value ({bad})")));
                }
                Ok(map_to_tensor(map, size, device))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Tensor::cat(maps, 0))
    }
}

fn not_found(path: &Path) -> Error {
    Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "prior file not found"))
}

/// A map as a `[1, 1, size]` tensor, resized when needed.
fn map_to_tensor(map: DepthMap, size: [usize; 2], device: &Device) -> Tensor<4> {
    let t = Tensor::<4>::from_data(TensorData::new(map.values, [1, 1, map.height, map.width]), device);
    resize_bilinear(t, size, true)
}

impl PriorProvider for FilePrior {
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>> {
        let [n, _, h, w] = input.left.dims();
        if input.names.len() != n {
            return Err(Error::Shape(format!(
                "file prior: {} names for a batch of {n}; PriorInput.names must name every pair",
                input.names.len()
            )));
        }
        let device = input.left.device();
        Ok(Some(DepthPrior {
            left: self.load_view(&self.left_pattern, &input.names, [h, w], &device)?,
            right: self.load_view(&self.right_pattern, &input.names, [h, w], &device)?,
        }))
    }
}
