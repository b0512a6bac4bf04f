//! `dgstereo._dgstereo.Engine`: the inference library's [`Engine`] as a Python class, which the
//! pure-Python `dgstereo.Model` wraps.
//!
//! One engine serves every thread: `predict` converts the arrays while it holds the
//! interpreter's lock, then releases it for the whole prediction ([`Python::detach`]), so calls
//! from several threads run at once (they share burn's thread pool, so each takes longer).

use std::path::PathBuf;

use dgstereo_inference::working_size::network_size;
use dgstereo_inference::{
    CorrChoice, Engine as LibEngine, EngineConfig, MinSize, ModelChoice, PredictOptions, PriorMaps,
};
use dgstereo_prior::PriorConfig;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays;
use crate::errors::{Kind, from_library, guarded, input};

/// A loaded model (see `dgstereo.Model`).
#[pyclass(module = "dgstereo._dgstereo", frozen)]
pub struct Engine {
    /// Boxed: the engine is aligned to 64 bytes, more than the interpreter aligns its objects.
    inner: Box<LibEngine>,
}

fn parse_corr(s: &str) -> PyResult<CorrChoice> {
    match s.to_ascii_lowercase().as_str() {
        "auto" => Ok(CorrChoice::Auto),
        "reg" => Ok(CorrChoice::Reg),
        "alt" => Ok(CorrChoice::Alt),
        _ => Err(input(format!("`corr` '{s}': expected auto, reg or alt"))),
    }
}

/// `weights` and the prior's weights as files: names of official checkpoints fetched by the
/// fetcher the environment describes (made only when a name needs it).
fn resolve_names(
    weights: Option<PathBuf>,
    prior: PriorConfig,
) -> dgstereo_core::Result<(Option<PathBuf>, PriorConfig)> {
    let weights_missing = weights.as_ref().is_some_and(|w| !w.exists());
    if !weights_missing && dgstereo_weights::check_resolved_prior(&prior, "prior").is_ok() {
        return Ok((weights, prior));
    }
    let fetcher = dgstereo_weights::Fetcher::from_env()?;
    let weights = weights.map(|w| fetcher.resolve_stereo(&w, "weights")).transpose()?;
    Ok((weights, fetcher.resolve_prior(prior, "prior")?))
}

#[pymethods]
impl Engine {
    #[new]
    // One argument per keyword of the Python constructor.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (weights=None, experiment=None, run=None, prior=None, device="cpu", precision="f32", slow_fast_gru=None, bundled_assets=None))]
    fn new(
        py: Python<'_>,
        weights: Option<PathBuf>,
        experiment: Option<PathBuf>,
        run: Option<String>,
        prior: Option<String>,
        device: &str,
        precision: &str,
        slow_fast_gru: Option<bool>,
        bundled_assets: Option<PathBuf>,
    ) -> PyResult<Self> {
        let device = device.parse().map_err(|e: dgstereo_core::Error| input(format!("`device`: {e}")))?;
        let precision = precision.parse().map_err(|e| input(format!("`precision`: {e}")))?;
        let choice = ModelChoice { experiment, run, prior, prior_weights: None };
        let (model, prior) = from_library(choice.configs(), Kind::Input)?;
        // Names of official checkpoints become files (fetched on first use, without progress
        // bars); the environment sets the cache, the servers, offline mode and the timeout.
        let (weights, prior) = from_library(py.detach(|| guarded(|| resolve_names(weights, prior))), Kind::Error)?;
        let config = EngineConfig { weights, model, prior, device, precision, slow_fast_gru, bundled_assets };
        let inner = py.detach(|| guarded(|| LibEngine::load_with_given_priors(&config)));
        Ok(Self { inner: Box::new(from_library(inner, Kind::Error)?) })
    }

    /// The weights file.
    #[getter]
    fn weights(&self) -> PathBuf {
        self.inner.weights().to_path_buf()
    }

    /// The model configuration as JSON (its serde form).
    #[getter]
    fn config_json(&self) -> PyResult<String> {
        serde_json::to_string(self.inner.model_config()).map_err(|e| input(e.to_string()))
    }

    /// The configuration on one line, with where it came from.
    #[getter]
    fn summary(&self) -> String {
        format!("{} ({})", self.inner.configuration_summary(), self.inner.configuration_source())
    }

    /// The iterations of an official checkpoint's preset, else `None`.
    #[getter]
    fn preset_iters(&self) -> Option<usize> {
        self.inner.preset_iters()
    }

    /// What loading chose on the caller's behalf.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.inner.notes().to_vec()
    }

    /// Whether the model uses a depth prior.
    #[getter]
    fn uses_prior(&self) -> bool {
        self.inner.model_config().needs_prior()
    }

    /// Whether each call must pass the prior maps.
    #[getter]
    fn takes_given_priors(&self) -> bool {
        self.inner.takes_given_priors()
    }

    /// Writes the model as an ONNX file for pairs of `height x width`, `iters` iterations
    /// unrolled; returns `(opset, nodes, inputs, outputs)`, each boundary as `(name, shape)`.
    #[allow(clippy::type_complexity)]
    fn export_onnx(
        &self,
        py: Python<'_>,
        path: PathBuf,
        height: usize,
        width: usize,
        iters: usize,
    ) -> PyResult<(i64, usize, Vec<(String, Vec<usize>)>, Vec<(String, Vec<usize>)>)> {
        let engine = &self.inner;
        let result = py.detach(|| {
            guarded(|| {
                let exported = dgstereo_export::export_onnx(engine.stereo_model(), height, width, iters)?;
                exported.write(&path)?;
                Ok(exported)
            })
        });
        let e = from_library(result, Kind::Error)?;
        Ok((dgstereo_export::OPSET, e.nodes, e.inputs, e.outputs))
    }

    /// The disparity of a pair and what happened (a dict).
    #[pyo3(signature = (left, right, iters, max_size=None, min_size="auto", memory_budget=dgstereo_inference::DEFAULT_MEMORY_BUDGET, corr="auto", lr_check=None, prior=None, name="pair", channels="rgb"))]
    #[allow(clippy::too_many_arguments)]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        left: &Bound<'py, PyAny>,
        right: &Bound<'py, PyAny>,
        iters: usize,
        max_size: Option<usize>,
        min_size: &str,
        memory_budget: u64,
        corr: &str,
        lr_check: Option<f32>,
        prior: Option<(Bound<'py, PyAny>, Bound<'py, PyAny>)>,
        name: &str,
        channels: &str,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
        let min_size: MinSize = min_size.parse().map_err(|e: String| input(format!("`min_size` {e}")))?;
        let options = PredictOptions { iters, max_size, min_size, memory_budget, corr: parse_corr(corr)?, lr_check };
        from_library(self.inner.check(&options), Kind::Input)?;
        let order = arrays::Channels::parse(channels)?;
        let (l, r) = (arrays::image(left, "left", order)?, arrays::image(right, "right", order)?);
        from_library(dgstereo_inference::check_same_size(&l, &r), Kind::Input)?;
        let min_size = self.inner.min_size(&options);
        from_library(network_size(l.width, l.height, min_size, options.max_size), Kind::Input)?;
        let maps = match &prior {
            Some((pl, pr)) => {
                Some(PriorMaps { left: arrays::map(pl, "prior[0]")?, right: arrays::map(pr, "prior[1]")? })
            }
            None => None,
        };
        match (&maps, self.inner.model_config().needs_prior()) {
            (Some(_), false) => return Err(input("`prior`: this model uses no depth prior; leave the prior maps out")),
            (None, true) if self.inner.takes_given_priors() => {
                return Err(input(
                    "this model uses a depth prior and none was configured: pass the pair's prior maps (`prior`)",
                ));
            }
            _ => {}
        }
        if let Some(m) = &maps {
            for (what, map) in [("prior[0]", &m.left), ("prior[1]", &m.right)] {
                if let Some(bad) = map.data.iter().find(|v| !v.is_finite()) {
                    return Err(input(format!("`{what}` holds a non-finite value ({bad})")));
                }
            }
        }
        let engine = &self.inner;
        let result = py.detach(|| {
            guarded(|| match &maps {
                Some(m) => engine.predict_with_prior(&l, &r, m, &options),
                None => engine.predict(&l, &r, name, &options),
            })
        });
        let prediction = from_library(result, Kind::Error)?;
        let info = PyDict::new(py);
        // (height, width), as NumPy writes every shape.
        let (width, height) = prediction.info.network_size;
        info.set_item("network_size", (height, width))?;
        info.set_item("corr", format!("{:?}", prediction.info.corr).to_ascii_lowercase())?;
        info.set_item("prior_seconds", prediction.info.prior_seconds)?;
        info.set_item("precision", prediction.info.precision)?;
        match prediction.info.rejected {
            Some(mask) => info.set_item("rejected", arrays::mask_to_array(py, mask)?)?,
            None => info.set_item("rejected", py.None())?,
        }
        Ok((arrays::map_to_array(py, prediction.disparity)?.into_any(), info))
    }
}
