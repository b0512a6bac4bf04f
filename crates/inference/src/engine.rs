//! The [`Engine`]: a loaded model with its prior, predicting the disparity of rectified pairs.
//!
//! Each prediction applies the [`PredictOptions`]:
//! - `max_size` downscales both views so the longer side is at most that many pixels, and
//!   `min_size` (default `auto`) upscales small pairs for 1/8-resolution models
//!   ([`crate::working_size`]); the disparity is resized back to the input size and multiplied
//!   by the inverse scale;
//! - the cost volume follows `corr` and `memory_budget` ([`crate::cost_volume`]);
//! - `lr_check` also runs the mirrored pair and fills the pixels the right view does not
//!   confirm ([`crate::consistency`]).
//!
//! Design decision: every whole-run problem (weights that do not load or do not fit the model
//! configuration, a prior that cannot be built, a device that does not exist) is found by
//! [`Engine::load`] and [`Engine::check`], once, before any pair is read, so a caller can fail
//! fast on those and keep going on per-pair ones.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::Device;
use dgstereo_core::device::Precision;
use dgstereo_core::{Error, Result};
use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_data::resize::{disparity_to_size, resize_rgb};
use dgstereo_data::{DisparityMap, Mask, RgbImage};
use dgstereo_kernels::{ProductPrecision, with_products};
use dgstereo_model::{ModelConfig, StereoModel};
use dgstereo_prior::{Prior, PriorConfig, PriorInput, PriorProvider};

use crate::consistency::{fill_rejected, mirror_disparity, mirror_rgb, rejected_pixels};
use crate::convert::{disparity_map, image_tensor};
use crate::cost_volume::{check_geometry_budget, corr_for};
use crate::options::{EngineConfig, PredictOptions, precision_name, split_precision};
pub use crate::prior_maps::PriorMaps;
use crate::weights::{default_weights_at, load_model};
use crate::working_size::network_size;

/// What happened on one pair.
#[derive(Clone, Debug, PartialEq)]
pub struct RunInfo {
    /// Size the network saw, `(width, height)` (after `max_size` / `min_size`).
    pub network_size: (usize, usize),
    /// Cost volume used.
    pub corr: CorrelationImplementation,
    /// With `lr_check`: the pixels the right view did not confirm (row-major, at the input's
    /// size), which the returned disparity has filled.
    pub rejected: Option<Mask>,
    /// Seconds spent computing the depth prior (both passes with `lr_check`); `None` without
    /// a prior.
    pub prior_seconds: Option<f64>,
    /// The precision the network ran in ([`crate::options::precision_name`]): `f32`, `f16`,
    /// `bf16` (the whole pass, on the GPU), or on the CPU `bf16 products (UNIT)`.
    pub precision: String,
}

impl RunInfo {
    /// With `lr_check`, the share of the pixels it replaced (0 to 1).
    pub fn rejected_share(&self) -> Option<f64> {
        self.rejected.as_ref().map(|m| m.count() as f64 / m.data.len().max(1) as f64)
    }
}

/// The result of [`Engine::predict`].
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// The left view's disparity in pixels, at the left image's size.
    pub disparity: DisparityMap,
    /// How it was computed.
    pub info: RunInfo,
}

/// Checks that the two views of a pair have one size.
pub fn check_same_size(left: &RgbImage, right: &RgbImage) -> Result<()> {
    if (left.width, left.height) != (right.width, right.height) {
        return Err(Error::Shape(format!(
            "left image is {}x{} but right image is {}x{}: the views of a rectified pair have one size",
            left.width, left.height, right.width, right.height
        )));
    }
    Ok(())
}

/// `e` with `context` written before its message ([`Error::context`]: its kind stays reachable
/// through [`Error::root`], so a caller that sorts errors by kind sorts it the same). A file that
/// could not be read is named by its path already and stays as it is.
fn within(e: Error, context: &str) -> Error {
    match e {
        io @ Error::Io { .. } => io,
        other => other.context(context),
    }
}

/// A loaded model with its prior.
///
/// `Send + Sync`, and [`Engine::predict`] takes `&self`: one engine may serve several threads.
pub struct Engine {
    model: StereoModel,
    prior: Option<Prior>,
    /// Whether the prior is read from precomputed files (which hold no mirrored views).
    file_prior: bool,
    weights: PathBuf,
    device: Device,
    notes: Vec<String>,
    /// The iterations of an official checkpoint's preset.
    preset_iters: Option<usize>,
    /// Where the model configuration came from.
    source: String,
    /// Whether a model with a depth prior was loaded without one, its maps given with each call.
    prior_per_call: bool,
    /// The device's float precision.
    precision: Precision,
    /// The precision of the host kernels' products (bf16 on the CPU with `precision` bf16).
    products: ProductPrecision,
}

impl Engine {
    /// Loads the weights into the configured model (see [`EngineConfig`]) and builds the prior.
    pub fn load(config: &EngineConfig) -> Result<Self> {
        Self::load_inner(config, false)
    }

    /// As [`Engine::load`], except that a model with a depth prior may load without `prior`:
    /// each pair's prior maps then come with [`Engine::predict_with_prior`].
    pub fn load_with_given_priors(config: &EngineConfig) -> Result<Self> {
        Self::load_inner(config, true)
    }

    fn load_inner(config: &EngineConfig, priors_given: bool) -> Result<Self> {
        let (precision, products) = split_precision(config.device, config.precision);
        let device = config.device.device_with_precision(precision)?;
        if precision != Precision::F32 && config.prior.gives_prior() {
            return Err(Error::config(
                "precision",
                format!("{}: the depth prior runs in f32 only; leave out `precision` or the prior", config.precision),
            ));
        }
        // Names of official checkpoints are files by now: the front end resolved them
        // (`dgstereo_weights::Fetcher`); one left over is refused, saying so.
        dgstereo_weights::check_resolved_prior(&config.prior, "prior")?;
        let prior_config = &config.prior;
        let mut notes = Vec::new();
        let weights = match &config.weights {
            Some(w) => dgstereo_weights::check_resolved(w, "weights").map(|()| w.clone())?,
            None => {
                let with_prior = prior_config.gives_prior() && config.model.is_none();
                let (path, note) = default_weights_at(config.bundled_assets.as_deref(), with_prior)?;
                notes.extend(note);
                path
            }
        };
        let from_experiment = config.model.is_some();
        let (mut model, detected) =
            load_model(&weights, config.model.clone(), &device).map_err(|e| match &config.model {
                Some(_) => within(e, &format!("weights {} do not fit the model configuration", weights.display())),
                None => within(e, &format!("cannot load weights {}", weights.display())),
            })?;
        if let Some(on) = config.slow_fast_gru {
            model.network.update_block.slow_fast_gru = on;
            model.config.updater.slow_fast_gru = on;
        }
        let preset_iters = detected.as_ref().map(|d| d.valid_iters);
        let source = match (&detected, from_experiment) {
            (Some(d), _) => format!("from the checkpoint's tensors; preset: {}", d.preset.name()),
            (None, true) => "from the given model configuration".into(),
            (None, false) => "from the weights file".into(),
        };
        let prior = if prior_config.gives_prior() {
            if prior_config.uses_ground_truth() {
                return Err(Error::config(
                    "prior",
                    "a simulated prior needs ground truth and cannot be used for inference",
                ));
            }
            if !model.config.needs_prior() {
                notes.push("this model uses no depth prior; `prior` is ignored".into());
                None
            } else {
                Some(prior_config.init(&device).map_err(|e| within(e, "`prior`"))?)
            }
        } else {
            None
        };
        let prior_per_call = priors_given && model.config.needs_prior() && prior.is_none();
        // The model's own check names the stage that needs the prior; the engine reports it
        // against its `prior` option, which is what the caller can set.
        if !prior_per_call && let Err(Error::Config(problem)) = model.config.check_prior(prior.is_some()) {
            return Err(Error::config(
                "prior",
                format!(
                    "this model uses a depth prior (its {}): set `prior` (Depth Anything V2 or files)",
                    problem.key
                ),
            ));
        }
        let file_prior = prior.is_some() && matches!(prior_config, PriorConfig::File { .. });
        Ok(Self {
            model,
            prior,
            file_prior,
            weights,
            device,
            notes,
            preset_iters,
            source,
            prior_per_call,
            precision,
            products,
        })
    }

    /// The weights file.
    pub fn weights(&self) -> &Path {
        &self.weights
    }

    /// The device.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The loaded network with its configuration (for an exporter that records its forward).
    pub fn stereo_model(&self) -> &StereoModel {
        &self.model
    }

    /// The model's configuration.
    pub fn model_config(&self) -> &ModelConfig {
        &self.model.config
    }

    /// The iterations the official preset of a `.pth` checkpoint's architecture runs (7 for the
    /// realtime model); `None` for other weights.
    pub fn preset_iters(&self) -> Option<usize> {
        self.preset_iters
    }

    /// The model configuration on one line ([`dgstereo_model::checkpoint_config::summary`]).
    pub fn configuration_summary(&self) -> String {
        dgstereo_model::checkpoint_config::summary(&self.model.config)
    }

    /// Where the configuration came from: the checkpoint's tensors (and which official preset),
    /// the given configuration, or the weights file.
    pub fn configuration_source(&self) -> &str {
        &self.source
    }

    /// The configuration on one line with the iterations of `options` and where it came from.
    pub fn describe(&self, options: &PredictOptions) -> String {
        format!("{}, {} iterations ({})", self.configuration_summary(), options.iters, self.source)
    }

    /// What loading chose on the caller's behalf and the caller may want to tell the user (a
    /// fallback to reference weights, a prior the model does not use).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Whether each pair's prior maps come with the call ([`Engine::load_with_given_priors`] of a
    /// model with a depth prior and no `prior` configured).
    pub fn takes_given_priors(&self) -> bool {
        self.prior_per_call
    }

    /// Checks `options` for this engine: [`PredictOptions::validate`], and that a left-right
    /// check has a prior of mirrored views.
    pub fn check(&self, options: &PredictOptions) -> Result<()> {
        options.validate()?;
        if options.lr_check.is_some() && self.file_prior {
            return Err(Error::config(
                "lr_check",
                "runs the mirrored pair, and a precomputed (file) prior has no mirrored views: use a Depth Anything V2 prior or leave out `lr_check`",
            ));
        }
        Ok(())
    }

    /// The longer side under which `options` upscale pairs for this model (`min_size` resolved).
    pub fn min_size(&self, options: &PredictOptions) -> Option<usize> {
        options.min_size.resolve(self.model.config.factor(), options.max_size)
    }

    /// The cost volume for a network input of `width x height` (before padding).
    pub fn choose_corr(&self, options: &PredictOptions, width: usize, height: usize) -> CorrelationImplementation {
        corr_for(&self.model.config, options.corr, options.memory_budget, width, height)
    }

    /// The disparity of a rectified pair at the left image's size (with `lr_check`, the pixels
    /// the right view does not confirm filled, and named in [`RunInfo::rejected`]). `name` is the
    /// pair's name, by which a file prior finds its maps; any name does without one.
    pub fn predict(
        &self,
        left: &RgbImage,
        right: &RgbImage,
        name: &str,
        options: &PredictOptions,
    ) -> Result<Prediction> {
        if self.prior_per_call {
            return Err(Error::config(
                "prior",
                "this model uses a depth prior and none was configured: pass the pair's prior maps (`prior`)",
            ));
        }
        self.predict_inner(left, right, name, None, options)
    }

    /// [`Engine::predict`] with the pair's depth prior computed elsewhere, in place of the
    /// configured provider's (with `lr_check`, the second pass sees the maps mirrored and
    /// swapped, as it sees the views).
    pub fn predict_with_prior(
        &self,
        left: &RgbImage,
        right: &RgbImage,
        prior: &PriorMaps,
        options: &PredictOptions,
    ) -> Result<Prediction> {
        if !self.model.config.needs_prior() {
            return Err(Error::config("prior", "this model uses no depth prior; leave the prior maps out"));
        }
        prior.check()?;
        self.predict_inner(left, right, "pair", Some(prior), options)
    }

    fn predict_inner(
        &self,
        left: &RgbImage,
        right: &RgbImage,
        name: &str,
        given: Option<&PriorMaps>,
        options: &PredictOptions,
    ) -> Result<Prediction> {
        self.check(options)?;
        check_same_size(left, right)?;
        let (disparity, info) = self.network_disparity(left, right, name, given, options)?;
        let Some(threshold) = options.lr_check else {
            return Ok(Prediction { disparity, info });
        };
        // The right view's disparity is the left one of the mirrored, swapped pair.
        let mirrored_prior = given.map(PriorMaps::mirrored);
        let (mirrored, mirrored_info) =
            self.network_disparity(&mirror_rgb(right), &mirror_rgb(left), name, mirrored_prior.as_ref(), options)?;
        let rejected = rejected_pixels(&disparity, &mirror_disparity(&mirrored), threshold)?;
        let filled = fill_rejected(&disparity, &rejected)?;
        let prior_seconds = info.prior_seconds.zip(mirrored_info.prior_seconds).map(|(a, b)| a + b);
        Ok(Prediction { disparity: filled, info: RunInfo { rejected: Some(rejected), prior_seconds, ..info } })
    }

    /// The network's disparity of a pair of one size, at that size.
    fn network_disparity(
        &self,
        left: &RgbImage,
        right: &RgbImage,
        name: &str,
        given: Option<&PriorMaps>,
        options: &PredictOptions,
    ) -> Result<(DisparityMap, RunInfo)> {
        let (w, h) = (left.width, left.height);
        let (scale, _) = network_size(w, h, self.min_size(options), options.max_size)?;
        let (l, r) = if scale != 1.0 {
            (resize_rgb(left, scale, scale), resize_rgb(right, scale, scale))
        } else {
            (left.clone(), right.clone())
        };
        // The last pass's freed buffers go back to the system where this pass's size differs;
        // a pass of the same size (the next frame, the mirrored pass) reuses them.
        dgstereo_kernels::allocator::release_before_pass([l.height, l.width]);
        let corr = self.choose_corr(options, l.width, l.height);
        check_geometry_budget(&self.model.config, options.memory_budget, l.width, l.height)?;
        let (lt, rt) = (image_tensor(&l, &self.device), image_tensor(&r, &self.device));
        let prior_start = Instant::now();
        let prior = match (given, &self.prior) {
            (Some(maps), _) => Some(maps.at_size([l.height, l.width], &self.device)),
            (None, Some(p)) => p.provide(&PriorInput {
                left: lt.clone(),
                right: rt.clone(),
                gt_disparity: None,
                names: vec![name.to_string()],
            })?,
            (None, None) => None,
        };
        let prior_seconds = prior.is_some().then(|| prior_start.elapsed().as_secs_f64());
        let pred = with_products(self.products, || {
            self.model.predict(lt, rt, prior.as_ref(), options.iters, false, Some(corr))
        })?;
        let small = disparity_map(pred.last());
        drop(pred);
        let precision = precision_name(self.precision, self.products);
        let info = RunInfo { network_size: (l.width, l.height), corr, rejected: None, prior_seconds, precision };
        Ok((disparity_to_size(&small, w, h)?, info))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_engine_can_be_shared_between_threads() {
        fn shared<T: Send + Sync>() {}
        shared::<Engine>();
    }

    #[test]
    fn the_bundled_default_predicts_at_the_input_size_with_each_policy() {
        use crate::working_size::MinSize;
        let engine = Engine::load(&EngineConfig::default()).unwrap();
        assert!(engine.weights().ends_with(crate::weights::DEFAULT_PLAIN), "{}", engine.weights().display());
        assert!(engine.notes().is_empty(), "{:?}", engine.notes());
        // A horizontal ramp seen 3 px apart: any trained model finds a positive disparity.
        let left = RgbImage::from_fn(64, 48, |x, y| [(x * 4) as f32, (y * 5) as f32, ((x * y) % 255) as f32]);
        let right =
            RgbImage::from_fn(64, 48, |x, y| [((x + 3) * 4) as f32, (y * 5) as f32, (((x + 3) * y) % 255) as f32]);
        let quick = PredictOptions { iters: 1, min_size: MinSize::Off, ..PredictOptions::default() };
        let p = engine.predict(&left, &right, "ramp", &quick).unwrap();
        assert_eq!((p.disparity.width, p.disparity.height), (64, 48));
        assert_eq!(
            (p.info.network_size, p.info.corr, p.info.rejected),
            ((64, 48), CorrelationImplementation::Reg, None)
        );
        let options = PredictOptions { max_size: Some(48), lr_check: Some(2.0), ..quick.clone() };
        let p = engine.predict(&left, &right, "ramp", &options).unwrap();
        assert_eq!((p.disparity.width, p.disparity.height), (64, 48));
        assert_eq!(p.info.network_size, (48, 36));
        // Pairs under the network's minimum are refused with their size, not enlarged.
        let (tiny_l, tiny_r) = (RgbImage::new(1, 1), RgbImage::new(1, 1));
        let auto = PredictOptions { iters: 1, ..PredictOptions::default() };
        let e = engine.predict(&tiny_l, &tiny_r, "tiny", &auto).unwrap_err();
        assert!(matches!(e, Error::Shape(_)) && e.to_string().contains("1x1"), "{e}");
        assert_eq!(p.info.rejected.map(|m| (m.width, m.height)), Some((64, 48)));
        // A tiny budget turns the materialised volume down; bad options name their field.
        let tight = PredictOptions { memory_budget: 1, ..quick.clone() };
        assert_eq!(engine.predict(&left, &right, "ramp", &tight).unwrap().info.corr, CorrelationImplementation::Alt);
        let e = engine.predict(&left, &right, "ramp", &PredictOptions { iters: 0, ..quick }).unwrap_err();
        assert!(e.to_string().contains("iters: must be at least 1"), "{e}");
    }

    #[test]
    fn a_model_with_a_prior_takes_given_maps_when_none_is_configured() {
        use crate::working_size::MinSize;
        let config = EngineConfig {
            weights: Some(crate::weights::asset(crate::weights::DEFAULT_WITH_PRIOR).unwrap()),
            ..EngineConfig::default()
        };
        let e = Engine::load(&config).err().expect("a prior model without a prior loads only with given maps");
        assert!(e.to_string().contains("set `prior`"), "{e}");
        let engine = Engine::load_with_given_priors(&config).unwrap();
        assert!(engine.takes_given_priors());
        let left = RgbImage::from_fn(64, 48, |x, y| [(x * 4) as f32, (y * 5) as f32, ((x * y) % 255) as f32]);
        let right =
            RgbImage::from_fn(64, 48, |x, y| [((x + 3) * 4) as f32, (y * 5) as f32, (((x + 3) * y) % 255) as f32]);
        let quick = PredictOptions { iters: 1, min_size: MinSize::Off, ..PredictOptions::default() };
        let e = engine.predict(&left, &right, "ramp", &quick).unwrap_err();
        assert!(e.to_string().contains("prior maps"), "{e}");
        // Maps of half the size, resized by the engine; the left-right check mirrors them.
        let ramp = |shift: f32| {
            DisparityMap::from_vec(32, 24, (0..32 * 24).map(|i| 1.0 + ((i % 32) as f32 + shift) / 32.0).collect())
                .unwrap()
        };
        let maps = PriorMaps { left: ramp(0.0), right: ramp(1.5) };
        let options = PredictOptions { lr_check: Some(2.0), ..quick };
        let p = engine.predict_with_prior(&left, &right, &maps, &options).unwrap();
        assert_eq!((p.disparity.width, p.disparity.height), (64, 48));
        assert!(p.disparity.data.iter().all(|d| d.is_finite()) && p.info.prior_seconds.is_some());
        let bad = PriorMaps { left: DisparityMap::filled(32, 24, f32::NAN), right: ramp(0.0) };
        let e = engine.predict_with_prior(&left, &right, &bad, &options).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
    }

    #[test]
    fn views_of_different_sizes_are_refused_naming_both_sizes() {
        let (a, b) = (RgbImage::new(40, 30), RgbImage::new(41, 30));
        assert!(check_same_size(&a, &a).is_ok());
        let e = check_same_size(&a, &b).unwrap_err().to_string();
        assert!(e.contains("40x30") && e.contains("41x30"), "{e}");
    }
}
