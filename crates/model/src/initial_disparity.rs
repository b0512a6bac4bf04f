//! The disparity initialiser: where the update loop starts.
//!
//! RAFT-Stereo starts from zero; DEFOM-Stereo from its monocular network's inverse depth, scaled
//! per sample; IGEV-Stereo from a soft-argmin of its geometry volume's classifier logits. The
//! initialiser is a concept of the composed network, not of one stage: it reads what other stages make (the
//! monocular network's depth here, the cost volume's aggregation for IGEV-Stereo), and stage
//! crates never see each other's outputs. So it lives beside the composition, in this crate, as a
//! configuration enum of its own (`[model.initial_disparity]`) that the forward pass asks once
//! per pass; it has no weights.

use burn::tensor::activation::softmax;
use burn::tensor::{Int, Tensor};
use dgstereo_core::{Error, MonocularFeatures, Problem, Result};
use serde::{Deserialize, Serialize};

/// DEFOM-Stereo's `idepth_scale`.
pub const DEFAULT_INVERSE_DEPTH_SCALE: f32 = 0.5;

fn default_scale() -> f32 {
    DEFAULT_INVERSE_DEPTH_SCALE
}

/// Which disparity the update loop starts from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum InitialDisparity {
    /// Zero (RAFT-Stereo).
    Zero {},
    /// DEFOM-Stereo's: the monocular inverse depth `m` at the update grid of width `w`,
    /// `m / (max(m) + 1e-8) · scale · w + 0.01` with the maximum per sample; the nearest point
    /// starts at `scale · w` (half the grid's width by default).
    ScaledInverseDepth {
        /// The largest initial disparity as a fraction of the update grid's width
        /// (`idepth_scale`, 0.5).
        #[serde(default = "default_scale")]
        scale: f32,
    },
    /// IGEV-Stereo's: the soft-argmin of the geometry encoding volume's classifier logits `l`
    /// over its disparities, `Σ_d softmax(l)_d · d` (`disparity_regression`), at the update grid.
    SoftArgmin {},
}

impl Default for InitialDisparity {
    fn default() -> Self {
        Self::Zero {}
    }
}

impl InitialDisparity {
    /// One configuration of every kind, with the reference's parameters, in the order of the
    /// enum (the kinds tests, property strategies and experiment checks draw from).
    pub fn variants() -> Vec<Self> {
        vec![Self::Zero {}, Self::scaled_inverse_depth(), Self::SoftArgmin {}]
    }

    /// DEFOM-Stereo's initialiser with its `idepth_scale` (0.5).
    pub fn scaled_inverse_depth() -> Self {
        Self::ScaledInverseDepth { scale: DEFAULT_INVERSE_DEPTH_SCALE }
    }

    /// The kind's name as the TOML key `kind` writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Zero {} => "zero",
            Self::ScaledInverseDepth { .. } => "scaled-inverse-depth",
            Self::SoftArgmin {} => "soft-argmin",
        }
    }

    /// Whether it reads a monocular network's inverse depth.
    pub fn needs_monocular(&self) -> bool {
        matches!(self, Self::ScaledInverseDepth { .. })
    }

    /// Whether it reads the geometry encoding volume's logits.
    pub fn needs_geometry(&self) -> bool {
        matches!(self, Self::SoftArgmin {})
    }

    /// Everything wrong with the parameters, keys relative to its table (`scale` must be a
    /// positive number).
    pub fn problems(&self) -> Vec<Problem> {
        match self {
            Self::ScaledInverseDepth { scale } if !(scale.is_finite() && *scale > 0.0) => {
                vec![Problem::new("scale", format!("{scale} is not a positive number"))]
            }
            _ => Vec::new(),
        }
    }

    /// The initial positive disparity at the update grid, `None` for zero.
    ///
    /// # Errors
    /// [`Error::Config`] keyed `initial_disparity.kind` when it needs the monocular features and
    /// `monocular` is `None`, or the geometry volume's logits and `geometry_logits` is `None`.
    ///
    /// # Shapes
    /// - `geometry_logits`: `[N, D, H/f, W/f]`
    /// - output: `[N, 1, H/f, W/f]`, the monocular inverse depth's or the logits' grid
    pub fn disparity(
        &self,
        monocular: Option<&MonocularFeatures>,
        geometry_logits: Option<&Tensor<4>>,
    ) -> Result<Option<Tensor<4>>> {
        match self {
            Self::Zero {} => Ok(None),
            Self::SoftArgmin {} => {
                let logits = geometry_logits.ok_or_else(|| {
                    Error::config(
                        "initial_disparity.kind",
                        "\"soft-argmin\" needs the geometry encoding volume: set model.correlation.geometry",
                    )
                })?;
                Ok(Some(soft_argmin(logits.clone())))
            }
            Self::ScaledInverseDepth { scale } => {
                let depth = &monocular
                    .ok_or_else(|| {
                        Error::config(
                            "initial_disparity.kind",
                            format!("\"{}\" needs a monocular network's inverse depth", self.kind()),
                        )
                    })?
                    .inverse_depth;
                let [n, _, h, w] = depth.dims();
                let max = depth.clone().detach().reshape([n, h * w]).max_dim(1).reshape([n, 1, 1, 1]);
                let scaled = (depth.clone() / max.add_scalar(1e-8)).mul_scalar(*scale).mul_scalar(w as f32);
                Ok(Some(scaled.add_scalar(0.01)))
            }
        }
    }
}

/// `Σ_d softmax(logits)_d · d` over dimension 1, in the reference's order (softmax, product,
/// sum).
///
/// # Shapes
/// - `logits`: `[N, D, H, W]`; output `[N, 1, H, W]`
pub fn soft_argmin(logits: Tensor<4>) -> Tensor<4> {
    let d = logits.dims()[1];
    let values = Tensor::<1, Int>::arange(0..d as i64, &logits.device()).float().reshape([1, d, 1, 1]);
    (softmax(logits, 1) * values).sum_dim(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::{from_vec, to_vec};

    #[test]
    fn every_kind_is_listed() {
        let listed: Vec<&str> = InitialDisparity::variants().iter().map(|v| v.kind()).collect();
        assert_eq!(listed, dgstereo_core::serde_names::accepted_kinds::<InitialDisparity>("kind").unwrap());
        for variant in InitialDisparity::variants() {
            let back: InitialDisparity =
                serde_json::from_str(&format!("{{\"kind\": \"{}\"}}", variant.kind())).unwrap();
            assert_eq!(back, variant);
        }
        assert!(serde_json::from_str::<InitialDisparity>("{\"kind\": \"zero\", \"scale\": 0.5}").is_err());
        assert_eq!(InitialDisparity::ScaledInverseDepth { scale: 0.0 }.problems()[0].key, "scale");
    }

    /// Per sample, the nearest point starts at `scale · w + 0.01` and the rest in proportion, in
    /// DEFOM-Stereo's order of float32 operations.
    #[test]
    fn scaled_inverse_depth_is_the_references() {
        let device = default_device();
        let (h, w) = (2, 4);
        let values: Vec<f32> =
            (0..2 * h * w).map(|i| if i < h * w { i as f32 * 0.3 } else { 7.0 - i as f32 * 0.2 }).collect();
        let depth = from_vec(values.clone(), [2, 1, h, w], &device);
        let monocular =
            MonocularFeatures { context: Vec::new(), left: depth.clone(), right: depth.clone(), inverse_depth: depth };
        let init = InitialDisparity::ScaledInverseDepth { scale: 0.5 };
        let out = to_vec(init.disparity(Some(&monocular), None).unwrap().unwrap());
        for (sample, chunk) in values.chunks(h * w).enumerate() {
            let max = chunk.iter().cloned().fold(f32::MIN, f32::max) + 1e-8;
            for (i, v) in chunk.iter().enumerate() {
                let expected = v / max * 0.5 * w as f32 + 0.01;
                assert_eq!(out[sample * h * w + i], expected, "sample {sample} element {i}");
            }
        }
        assert!(InitialDisparity::Zero {}.disparity(None, None).unwrap().is_none());
        assert!(init.disparity(None, None).is_err());
    }

    /// The soft-argmin is the softmax-weighted mean disparity: logits peaked at one disparity
    /// give it, equal logits the middle of the range; without logits it is an error naming the
    /// key.
    #[test]
    fn soft_argmin_is_the_expected_disparity() {
        let device = default_device();
        let d = 6;
        let mut values = vec![0.0f32; 2 * d];
        values[4] = 50.0;
        let logits = from_vec(values, [1, d, 1, 2], &device);
        let init = InitialDisparity::SoftArgmin {};
        let out = to_vec(init.disparity(None, Some(&logits)).unwrap().unwrap());
        // Pixel 0 peaks at disparity 2 (element 4 = d 2, x 0); pixel 1 is flat.
        assert!((out[0] - 2.0).abs() < 1e-5, "{out:?}");
        assert!((out[1] - 2.5).abs() < 1e-5, "{out:?}");
        let e = init.disparity(None, None).unwrap_err().to_string();
        assert!(e.contains("initial_disparity.kind") && e.contains("geometry"), "{e}");
    }
}
