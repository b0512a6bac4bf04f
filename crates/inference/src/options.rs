//! What an [`crate::Engine`] is loaded from ([`EngineConfig`]) and what each prediction is asked
//! to do ([`PredictOptions`]).
//!
//! Design decision: the two are apart because they change at different rates: loading reads the
//! weights and builds the prior (seconds), while the per-pair policy is free to change from one
//! call to the next. Problems with the options are configuration errors keyed by the field
//! ([`Error::config`]`("min_size", ..)`), which a front end translates into its own spelling (a
//! flag, a keyword argument).

use std::path::PathBuf;

use dgstereo_core::device::Precision;
use dgstereo_core::{DeviceChoice, Error, Result};
use dgstereo_kernels::ProductPrecision;
use dgstereo_model::ModelConfig;
use dgstereo_prior::PriorConfig;

use crate::cost_volume::{CorrChoice, DEFAULT_MEMORY_BUDGET};
use crate::working_size::{MIN_WORKING_SIZE, MinSize};

/// What to load: the weights, the model and prior configurations, the device.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineConfig {
    /// Weights: a dgstereo `.safetensors` or an official RAFT-Stereo or DEFOM-Stereo `.pth`; `None` for the
    /// bundled default ([`crate::weights::default_weights`]). A name of an official checkpoint
    /// is resolved to its file first (`dgstereo_weights::Fetcher::resolve_stereo`).
    pub weights: Option<PathBuf>,
    /// The model configuration the weights were trained with; `None` for the one a
    /// `.safetensors` file carries, else RAFT-Stereo's default.
    pub model: Option<ModelConfig>,
    /// The depth prior (used only by models with fusion or guidance).
    pub prior: PriorConfig,
    /// The device.
    pub device: DeviceChoice,
    /// Float precision of the network: f32, or f16 / bf16 (weights cast after loading; for
    /// GPUs, whose tensor cores multiply half precision; not with a depth prior). On the CPU,
    /// bf16 means f32 activations with the host kernels' products in bf16 on the processor's
    /// bf16 unit ([`split_precision`]).
    pub precision: Precision,
    /// The slow-fast GRU schedule, replacing the configuration's (an official checkpoint's
    /// preset or the experiment's) where given.
    pub slow_fast_gru: Option<bool>,
    /// A folder holding the bundled `weights/` (a Python package's data), searched for the
    /// default weights instead of the checkout's and the binary's `assets/` (`DGSTEREO_ASSETS`
    /// still first); `None` for those.
    pub bundled_assets: Option<PathBuf>,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            weights: None,
            model: None,
            prior: PriorConfig::None {},
            device: DeviceChoice::default(),
            precision: Precision::F32,
            slow_fast_gru: None,
            bundled_assets: None,
        }
    }
}

/// How one pair is predicted.
#[derive(Clone, Debug, PartialEq)]
pub struct PredictOptions {
    /// Update iterations (at least 1).
    pub iters: usize,
    /// Pairs whose longer side exceeds this many pixels are downscaled to it.
    pub max_size: Option<usize>,
    /// Pairs whose longer side is under this are upscaled to it ([`MinSize`]).
    pub min_size: MinSize,
    /// Bytes the materialised cost volume may take with [`CorrChoice::Auto`], and the most
    /// IGEV-Stereo's geometry encoding volume may take ([`crate::cost_volume::check_geometry_budget`]).
    pub memory_budget: u64,
    /// Cost volume implementation.
    pub corr: CorrChoice,
    /// Left-right consistency check at this threshold in pixels ([`crate::consistency`]):
    /// runs the mirrored pair too, and fills the pixels the right view does not confirm.
    pub lr_check: Option<f32>,
}

impl Default for PredictOptions {
    fn default() -> Self {
        Self {
            iters: 32,
            max_size: None,
            min_size: MinSize::Auto,
            memory_budget: DEFAULT_MEMORY_BUDGET,
            corr: CorrChoice::Auto,
            lr_check: None,
        }
    }
}

impl PredictOptions {
    /// Checks the options on their own (an engine adds what depends on its model and prior).
    pub fn validate(&self) -> Result<()> {
        if self.iters == 0 {
            return Err(Error::config("iters", "must be at least 1"));
        }
        if self.max_size.is_some_and(|m| m < MIN_WORKING_SIZE) {
            return Err(Error::config("max_size", format!("must be at least {MIN_WORKING_SIZE} pixels")));
        }
        // `Auto` never conflicts: it is off with a `max_size`.
        match (self.min_size, self.max_size) {
            (MinSize::Pixels(lo), Some(hi)) if lo > hi => {
                return Err(Error::config("min_size", format!("{lo} is larger than `max_size` {hi}")));
            }
            (MinSize::Pixels(lo), _) if lo < MIN_WORKING_SIZE => {
                return Err(Error::config(
                    "min_size",
                    format!("must be at least {MIN_WORKING_SIZE} pixels (or `off`)"),
                ));
            }
            _ => {}
        }
        if let Some(t) = self.lr_check
            && !(t.is_finite() && t > 0.0)
        {
            return Err(Error::config("lr_check", format!("{t}: the threshold must be a positive number of pixels")));
        }
        Ok(())
    }
}

/// What `precision` on `device` computes in: the device's float precision and the host kernels'
/// products. On the CPU, bf16 is f32 activations with bf16 products (f32 sums) on the
/// processor's bf16 unit, where it has one (the products stay f32 where it has none); elsewhere
/// the precision is the device's, with f32 products.
pub fn split_precision(device: DeviceChoice, precision: Precision) -> (Precision, ProductPrecision) {
    match (device, precision) {
        (DeviceChoice::Cpu, Precision::Bf16) => (Precision::F32, ProductPrecision::Bf16),
        _ => (precision, ProductPrecision::F32),
    }
}

/// How the run of [`split_precision`]'s pair is named in reports: the device's precision, or
/// `bf16 products (UNIT)` with the processor's bf16 unit (`f32 (no bf16 unit)` where it has
/// none).
pub fn precision_name(precision: Precision, products: ProductPrecision) -> String {
    match (products, dgstereo_kernels::bf16_unit()) {
        (ProductPrecision::F32, _) => precision.to_string(),
        (ProductPrecision::Bf16, Some(unit)) => format!("bf16 products ({unit})"),
        (ProductPrecision::Bf16, None) => "f32 (bf16 asked; the processor has no bf16 unit)".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_options_name_their_fields() {
        assert!(PredictOptions::default().validate().is_ok());
        for (options, message) in [
            (PredictOptions { iters: 0, ..Default::default() }, "iters: must be at least 1"),
            (PredictOptions { max_size: Some(16), ..Default::default() }, "max_size: must be at least 32"),
            (
                PredictOptions { min_size: MinSize::Pixels(300), max_size: Some(200), ..Default::default() },
                "min_size: 300 is larger than `max_size` 200",
            ),
            (PredictOptions { min_size: MinSize::Pixels(8), ..Default::default() }, "min_size: must be at least"),
            (PredictOptions { lr_check: Some(0.0), ..Default::default() }, "lr_check: 0: the threshold"),
        ] {
            let e = options.validate().unwrap_err().to_string();
            assert!(e.contains(message), "{e}");
        }
        // An automatic lower bound does not conflict with a cap.
        assert!(PredictOptions { max_size: Some(100), ..Default::default() }.validate().is_ok());
    }

    /// bf16 on the CPU is f32 activations with bf16 products; elsewhere the device's precision.
    #[test]
    fn bf16_on_the_cpu_means_bf16_products() {
        use dgstereo_kernels::ProductPrecision::{Bf16, F32};
        assert_eq!(split_precision(DeviceChoice::Cpu, Precision::Bf16), (Precision::F32, Bf16));
        assert_eq!(split_precision(DeviceChoice::Cpu, Precision::F16), (Precision::F16, F32));
        assert_eq!(split_precision(DeviceChoice::Gpu, Precision::Bf16), (Precision::Bf16, F32));
        assert_eq!(precision_name(Precision::F32, F32), "f32");
        let name = precision_name(Precision::F32, Bf16);
        assert!(name.starts_with("bf16 products (") || name.starts_with("f32 (bf16 asked"), "{name}");
    }
}
