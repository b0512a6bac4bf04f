//! Training batches, a pure function of `(seed, step)`.
//!
//! Design decision: nothing in the data path carries a running random state. Element `b` of step
//! `k` draws its source, its pair and its augmentation from a ChaCha8 generator seeded by a hash
//! of `(seed, k, b)`. So the batch of any step can be rebuilt from the config alone, which is what
//! makes a resumed run equal an uninterrupted one, and the checkpoint's "RNG state" is just the
//! seed and the step counter.

use std::path::Path;

use burn::tensor::{Device, Tensor};
use dgstereo_core::{Error, Result};
use dgstereo_data::datasets::{KittiVersion, SceneFlowPass, SceneFlowSubset};
use dgstereo_data::{AugmentConfig, Dataset, DisparityMap, FileDataset, Mask, RgbImage, SyntheticConfig, synthetic};
use dgstereo_experiment::{DataSource, TrainingConfig, TrainingDataConfig};
use dgstereo_loss::LossTarget;
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// SplitMix64 finaliser: a well-mixed 64-bit hash of `x`.
pub fn mix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// The seed of element `element` of step `step` of a run seeded `seed`.
pub fn element_seed(seed: u64, step: usize, element: usize) -> u64 {
    mix64(mix64(mix64(seed) ^ step as u64) ^ (element as u64).wrapping_mul(0xA24B_AED4_963E_E407))
}

/// One training pair after augmentation, all maps of the crop's size.
#[derive(Debug, Clone)]
pub struct TrainingPair {
    /// Which pair it is (source and index or scene seed).
    pub name: String,
    /// Left view, RGB 0..255.
    pub left: RgbImage,
    /// Right view.
    pub right: RgbImage,
    /// Ground truth resized bilinearly.
    pub disparity: DisparityMap,
    /// Ground truth resized by nearest neighbour.
    pub disparity_nearest: DisparityMap,
    /// Valid ground truth.
    pub valid: Mask,
}

enum Source {
    Synthetic { config: Box<SyntheticConfig>, count: Option<usize>, base_seed: u64 },
    Files { name: String, dataset: FileDataset, sparse: bool },
}

/// The configured training sources, ready to draw pairs from.
pub struct TrainingData {
    sources: Vec<Source>,
    cumulative: Vec<f64>,
    augment: Option<AugmentConfig>,
    crop: [usize; 2],
    seed: u64,
}

fn dataset(source: &DataSource, index: usize) -> Result<Option<(String, FileDataset)>> {
    let key = |k: &str| format!("data.sources[{index}].{k}");
    let check_root = |root: &Path| {
        if root.is_dir() {
            Ok(())
        } else {
            Err(Error::config(key("root"), format!("'{}': no such folder", root.display())))
        }
    };
    let ds = match source {
        DataSource::Synthetic { .. } => return Ok(None),
        DataSource::Sceneflow { root, subset, pass, .. } => {
            check_root(root)?;
            let subset = match subset.as_str() {
                "flyingthings" | "flyingthings3d" => SceneFlowSubset::FlyingThingsTrain,
                "driving" => SceneFlowSubset::Driving,
                "monkaa" => SceneFlowSubset::Monkaa,
                other => {
                    return Err(Error::config(
                        key("subset"),
                        format!("'{other}': expected flyingthings, driving or monkaa"),
                    ));
                }
            };
            let pass = match pass.as_str() {
                "clean" => SceneFlowPass::Clean,
                "final" => SceneFlowPass::Final,
                other => return Err(Error::config(key("pass"), format!("'{other}': expected clean or final"))),
            };
            ("sceneflow", dgstereo_data::datasets::sceneflow(root, subset, pass)?)
        }
        DataSource::Middlebury { root, .. } => {
            check_root(root)?;
            ("middlebury", dgstereo_data::datasets::middlebury2014(root)?)
        }
        DataSource::Eth3d { root, .. } => {
            check_root(root)?;
            ("eth3d", dgstereo_data::datasets::eth3d(root)?)
        }
        DataSource::Kitti { root, version, .. } => {
            check_root(root)?;
            let v = match version {
                2012 => KittiVersion::K2012,
                2015 => KittiVersion::K2015,
                other => return Err(Error::config(key("version"), format!("{other}: expected 2012 or 2015"))),
            };
            ("kitti", dgstereo_data::datasets::kitti(root, v)?)
        }
        DataSource::Folder { root, .. } => {
            check_root(root)?;
            ("folder", dgstereo_data::datasets::folder_pairs(root)?)
        }
    };
    let (name, ds) = ds;
    if ds.files.is_empty() {
        return Err(Error::config(format!("data.sources[{index}]"), format!("the {name} source lists no pairs")));
    }
    if ds.files.iter().any(|f| f.disparity.is_none()) {
        return Err(Error::config(
            format!("data.sources[{index}]"),
            format!("some pairs of the {name} source have no ground truth"),
        ));
    }
    Ok(Some((name.to_string(), ds)))
}

impl TrainingData {
    /// Lists the sources (datasets are only listed here, read on demand).
    pub fn new(data: &TrainingDataConfig, train: &TrainingConfig) -> Result<Self> {
        data.validate()?;
        data.check_files()?;
        let mut sources = Vec::new();
        for (i, s) in data.sources.iter().enumerate() {
            match dataset(s, i)? {
                Some((name, dataset)) => sources.push(Source::Files { name, dataset, sparse: s.sparse_ground_truth() }),
                None => {
                    let (DataSource::Synthetic { count, .. }, Some(config)) = (s, s.synthetic()) else {
                        unreachable!("`dataset` lists every source but the synthetic one")
                    };
                    sources.push(Source::Synthetic {
                        config: Box::new(config),
                        count: *count,
                        base_seed: mix64(train.seed ^ i as u64),
                    });
                }
            }
        }
        let mut total = 0.0;
        let cumulative = data.sources.iter().map(|s| {
            total += s.weight();
            total
        });
        let cumulative = cumulative.collect();
        let augment = data.augment.then(|| AugmentConfig {
            min_scale: data.spatial_scale[0],
            max_scale: data.spatial_scale[1],
            saturation: data.saturation_range,
            ..AugmentConfig::with_crop(train.crop[0], train.crop[1])
        });
        Ok(Self { sources, cumulative, augment, crop: train.crop, seed: train.seed })
    }

    /// Element `element` of step `step` (deterministic).
    pub fn pair(&self, step: usize, element: usize) -> Result<TrainingPair> {
        let mut rng = ChaCha8Rng::seed_from_u64(element_seed(self.seed, step, element));
        let total = *self.cumulative.last().expect("at least one source");
        let u = rng.gen_range(0.0..total);
        let which = self.cumulative.iter().position(|&c| u < c).unwrap_or(self.sources.len() - 1);
        let sparse = matches!(self.sources[which], Source::Files { sparse: true, .. });
        let (name, left, right, disparity, valid) = match &self.sources[which] {
            Source::Synthetic { config, count, base_seed } => {
                let scene = match count {
                    Some(c) => base_seed.wrapping_add(rng.gen_range(0..*c) as u64),
                    None => rng.next_u64(),
                };
                let s = synthetic::generate(config, scene);
                (format!("synthetic/{scene}"), s.left, s.right, s.disparity, s.valid)
            }
            Source::Files { name, dataset, .. } => {
                let index = rng.gen_range(0..dataset.len());
                let s = dataset.get(index)?;
                let (Some(d), Some(v)) = (s.disparity, s.valid) else {
                    let reason = format!("no ground truth; a training source of {name} needs disparity files");
                    return Err(Error::sample(s.name, reason));
                };
                (format!("{name}/{}", s.name), s.left, s.right, d, v)
            }
        };
        let aug_seed = rng.next_u64();
        let [ch, cw] = self.crop;
        match &self.augment {
            Some(cfg) => {
                let augment = if sparse { dgstereo_data::augment_sparse } else { dgstereo_data::augment };
                let a = augment(cfg, &left, &right, &disparity, Some(&valid), aug_seed)
                    .map_err(|e| e.context(name.clone()))?;
                Ok(TrainingPair {
                    name,
                    left: a.left,
                    right: a.right,
                    disparity: a.disparity,
                    disparity_nearest: a.disparity_nearest,
                    valid: a.valid,
                })
            }
            None => {
                let (w, h) = (left.width, left.height);
                if w < cw || h < ch {
                    return Err(Error::Shape(format!("{name}: image {w}x{h} is smaller than train.crop {cw}x{ch}")));
                }
                let x0 = rng.gen_range(0..=w - cw);
                let y0 = rng.gen_range(0..=h - ch);
                let disparity = disparity.crop(x0, y0, cw, ch)?;
                Ok(TrainingPair {
                    name,
                    left: left.crop(x0, y0, cw, ch)?,
                    right: right.crop(x0, y0, cw, ch)?,
                    disparity_nearest: disparity.clone(),
                    disparity,
                    valid: valid.crop(x0, y0, cw, ch)?,
                })
            }
        }
    }

    /// The pairs of step `step`, built in parallel.
    pub fn batch(&self, step: usize, batch_size: usize) -> Result<Vec<TrainingPair>> {
        (0..batch_size).into_par_iter().map(|b| self.pair(step, b)).collect()
    }
}

/// A batch as tensors.
///
/// # Shapes
/// - `left`, `right`: `[N, 3, H, W]`, RGB 0..255
/// - target maps: `[N, 1, H, W]`
#[derive(Debug, Clone)]
pub struct TensorBatch {
    /// Left views.
    pub left: Tensor<4>,
    /// Right views.
    pub right: Tensor<4>,
    /// What the loss compares with.
    pub target: LossTarget,
    /// Names of the pairs.
    pub names: Vec<String>,
}

/// Stacks pairs (all of one size) into tensors on `device`.
pub fn to_tensors(pairs: &[TrainingPair], device: &Device) -> Result<TensorBatch> {
    let first = pairs.first().ok_or_else(|| Error::Shape("an empty batch: no pairs to stack".into()))?;
    let (w, h) = (first.left.width, first.left.height);
    if let Some(p) = pairs.iter().find(|p| (p.left.width, p.left.height) != (w, h)) {
        return Err(Error::Shape(format!(
            "batch mixes sizes: {} is {}x{}, {} is {w}x{h}",
            p.name, p.left.width, p.left.height, first.name
        )));
    }
    let n = pairs.len();
    let mut left = Vec::with_capacity(n * 3 * h * w);
    let mut right = Vec::with_capacity(n * 3 * h * w);
    let mut bil = Vec::with_capacity(n * h * w);
    let mut near = Vec::with_capacity(n * h * w);
    let mut valid = Vec::with_capacity(n * h * w);
    for p in pairs {
        left.extend_from_slice(&p.left.data);
        right.extend_from_slice(&p.right.data);
        // Non-finite ground truth is invalid; zero it so no NaN enters the graph.
        for ((&d, &dn), &v) in p.disparity.data.iter().zip(&p.disparity_nearest.data).zip(&p.valid.data) {
            let ok = v && d.is_finite() && dn.is_finite();
            bil.push(if ok { d } else { 0.0 });
            near.push(if dn.is_finite() { dn } else { 0.0 });
            valid.push(if ok { 1.0 } else { 0.0 });
        }
    }
    use dgstereo_core::tensor::from_vec;
    Ok(TensorBatch {
        left: from_vec(left, [n, 3, h, w], device),
        right: from_vec(right, [n, 3, h, w], device),
        target: LossTarget {
            disparity_bilinear: from_vec(bil, [n, 1, h, w], device),
            disparity_nearest: from_vec(near, [n, 1, h, w], device),
            valid: from_vec(valid, [n, 1, h, w], device),
        },
        names: pairs.iter().map(|p| p.name.clone()).collect(),
    })
}
