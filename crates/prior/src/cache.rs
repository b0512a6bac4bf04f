//! The `cache` prior provider: another provider's outputs, stored on disk.
//!
//! Each batch element is keyed by a 128-bit hash of its content, never its name: the bytes of
//! the left and right images (and of the ground truth when the wrapped provider reads it), their
//! size, and a fingerprint of the wrapped provider's configuration (its JSON). Changing a
//! weight file path, the input size or the seed therefore misses the cache instead of returning
//! stale priors. A hit reads `<dir>/<key>.safetensors` (`left`, `right`: `[H, W]` float32);
//! misses are computed together in one call of the wrapped provider and written atomically
//! (temporary file, then rename). The hash is not cryptographic; it guards against mistakes,
//! not adversaries.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Int, Tensor, TensorData};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, Result};

use crate::content_hash::ContentHasher;
use crate::safetensors_io::{FloatArray, read_float_tensors, write_float_tensors};
use crate::{DepthPrior, PriorInput, PriorProvider};

/// Version of the key derivation and file layout; bump to invalidate old caches.
const CACHE_VERSION: &str = "dgstereo-prior-cache v1";

/// Caches the outputs of a wrapped provider `P` on disk.
#[derive(Debug, Clone)]
pub struct CachedPrior<P> {
    inner: P,
    fingerprint: String,
    dir: PathBuf,
    hash_ground_truth: bool,
}

impl<P: PriorProvider> CachedPrior<P> {
    /// Wraps `inner`, whose configuration is summarised by `fingerprint` (any string that changes
    /// whenever its output would), storing files in `dir` (created when missing).
    /// `hash_ground_truth` adds the ground truth to the key, for providers that read it.
    pub fn new(
        inner: P,
        fingerprint: impl Into<String>,
        dir: impl Into<PathBuf>,
        hash_ground_truth: bool,
    ) -> Result<Self> {
        let dir = dir.into();
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        Ok(Self { inner, fingerprint: fingerprint.into(), dir, hash_ground_truth })
    }

    /// The wrapped provider.
    pub fn inner(&self) -> &P {
        &self.inner
    }

    /// The cache file of each batch element.
    pub fn entry_paths(&self, input: &PriorInput) -> Vec<PathBuf> {
        let [n, _, h, w] = input.left.dims();
        let left = to_vec(input.left.clone());
        let right = to_vec(input.right.clone());
        let gt = input.gt_disparity.as_ref().filter(|_| self.hash_ground_truth).map(|g| to_vec(g.clone()));
        let image_len = left.len() / n.max(1);
        let gt_len = gt.as_ref().map_or(0, |g| g.len() / n.max(1));
        (0..n)
            .map(|i| {
                let mut hasher = ContentHasher::default();
                hasher.update(CACHE_VERSION.as_bytes());
                hasher.update(self.fingerprint.as_bytes());
                hasher.update(&[h as u64, w as u64].map(u64::to_le_bytes).concat());
                for values in [&left[i * image_len..(i + 1) * image_len], &right[i * image_len..(i + 1) * image_len]] {
                    hasher.update(&values.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
                }
                if let Some(gt) = &gt {
                    hasher.update(
                        &gt[i * gt_len..(i + 1) * gt_len].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>(),
                    );
                }
                self.dir.join(format!("{}.safetensors", hasher.hex()))
            })
            .collect()
    }
}

fn read_entry(path: &Path, size: [usize; 2], device: &Device) -> Result<[Tensor<4>; 2]> {
    let mut tensors = read_float_tensors(path)?;
    let mut view = |key: &str| -> Result<Tensor<4>> {
        let a = tensors.remove(key).ok_or_else(|| Error::format(path, format!("cache entry lacks '{key}'")))?;
        if a.shape != size {
            return Err(Error::format(path, format!("cache entry '{key}' has shape {:?}, expected {size:?}", a.shape)));
        }
        Ok(Tensor::from_data(TensorData::new(a.values, [1, 1, size[0], size[1]]), device))
    };
    Ok([view("left")?, view("right")?])
}

fn write_entry(path: &Path, left: Tensor<4>, right: Tensor<4>) -> Result<()> {
    let [_, _, h, w] = left.dims();
    let tensors: BTreeMap<String, FloatArray> = [("left", left), ("right", right)]
        .into_iter()
        .map(|(k, t)| (k.to_string(), FloatArray { shape: vec![h, w], values: to_vec(t) }))
        .collect();
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    let metadata = HashMap::from([("format".to_string(), CACHE_VERSION.to_string())]);
    write_float_tensors(&tmp, &tensors, Some(metadata))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

fn select(t: &Tensor<4>, indices: &[usize]) -> Tensor<4> {
    let device = t.device();
    let idx = Tensor::<1, Int>::from_data(
        TensorData::new(indices.iter().map(|&i| i as i64).collect::<Vec<_>>(), [indices.len()]),
        &device,
    );
    t.clone().select(0, idx)
}

impl<P: PriorProvider> PriorProvider for CachedPrior<P> {
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>> {
        let [n, _, h, w] = input.left.dims();
        let device = input.left.device();
        let paths = self.entry_paths(input);
        let mut views: Vec<Option<[Tensor<4>; 2]>> = Vec::with_capacity(n);
        for path in &paths {
            views.push(if path.is_file() { Some(read_entry(path, [h, w], &device)?) } else { None });
        }
        let missing: Vec<usize> = (0..n).filter(|&i| views[i].is_none()).collect();
        if !missing.is_empty() {
            let sub = PriorInput {
                left: select(&input.left, &missing),
                right: select(&input.right, &missing),
                gt_disparity: input.gt_disparity.as_ref().map(|g| select(g, &missing)),
                names: missing.iter().filter_map(|&i| input.names.get(i).cloned()).collect(),
            };
            let Some(computed) = self.inner.provide(&sub)? else {
                return Ok(None);
            };
            for (k, &i) in missing.iter().enumerate() {
                let left = computed.left.clone().narrow(0, k, 1);
                let right = computed.right.clone().narrow(0, k, 1);
                write_entry(&paths[i], left.clone(), right.clone())?;
                views[i] = Some([left, right]);
            }
        }
        let (left, right): (Vec<_>, Vec<_>) = views.into_iter().map(|v| v.expect("filled").into()).unzip();
        Ok(Some(DepthPrior { left: Tensor::cat(left, 0), right: Tensor::cat(right, 0) }))
    }
}
