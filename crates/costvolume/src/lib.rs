//! The 1-D correlation cost volume of RAFT-Stereo and its lookup.
//!
//! Rectified stereo only matches along rows, so the volume is `corr[n,h,x1,x2] = <f1[:,h,x1],
//! f2[:,h,x2]> / sqrt(C)`, pooled by 2 along `x2` into a pyramid and sampled by linear
//! interpolation at `x = coords / 2^level + dx`, `dx = -r..=r` (zero outside the row).
//! Two implementations sit behind the [`CostVolume`] trait: [`CorrelationPyramid`] materialises
//! the `W x W` volume per row once (fast lookups; "reg" in the reference) and
//! [`OnTheFlyCorrelation`] stores only the pooled features and takes the dot products at the
//! sampled positions (memory linear in `W`; "alt"). They agree to float rounding. Both are the
//! kernels crate's lookups (`dgstereo_kernels::CorrelationPyramid`, `OnTheFlyCorrelation`), which keep their data where the
//! dispatch's path samples it: host buffers and one loop for CPU inference, gathered levels for
//! GPU inference, burn's tensor operations (the reference and the differentiable path)
//! elsewhere. This crate is the stage: its configuration, its trait and the choice between the
//! two.
//!
//! DEFOM-Stereo adds a second lookup of the same volume ([`ScaleLookup`]): its level 0 sampled
//! around the matches of scaled disparities, `x - s·d` for each scale `s`, for the update block
//! that rescales the disparity.
//!
//! IGEV-Stereo builds another volume from the same kind of features ([`GeometryVolume`]): the
//! group-wise correlation of match features over `max_disp / 4` disparities, aggregated by 3-D
//! convolutions gated by the image features ([`GeometryEncoding`]) into a geometry encoding
//! volume, whose classifier's soft-argmin starts the loop; its lookup
//! ([`CombinedGeometryVolume`], [`Correlation::Geometry`]) joins that volume sampled at the
//! disparity with the plain all-pairs correlation sampled at the match, the latter stored or on
//! the fly as the implementation choice says.
#![deny(missing_docs)]

pub mod basic_conv;
pub mod combined_lookup;
pub mod feature_attention;
pub mod geometry;
pub mod hourglass;

use burn::tensor::Tensor;
use dgstereo_core::Problem;
pub use dgstereo_kernels::{CorrelationPyramid, OnTheFlyCorrelation, all_pairs};
use serde::{Deserialize, Serialize};

pub use combined_lookup::CombinedGeometryVolume;
pub use geometry::{GeometryEncoding, GeometryOutput, GeometryVolume};

/// The stage trait: correlation features around the current match positions.
///
/// # Shapes
/// - `coords_x`: `[N, 1, H, W]`, x position in the right feature map of each left pixel
/// - output: `[N, levels · (2·radius + 1), H, W]`, level-major, offsets ascending
pub trait CostVolume {
    /// Samples the volume around `coords_x`.
    fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4>;
}

/// Which implementation builds the volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum CorrelationImplementation {
    /// Materialised all-pairs pyramid ("reg").
    #[default]
    Reg,
    /// On-the-fly dot products, never storing the `W x W` volume ("alt").
    Alt,
}

/// Configuration of the correlation stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrelationConfig {
    /// Implementation.
    #[serde(default)]
    pub implementation: CorrelationImplementation,
    /// Pyramid levels looked up (`corr_levels`, 4).
    #[serde(default = "default_levels")]
    pub levels: usize,
    /// Lookup radius (`corr_radius`, 4).
    #[serde(default = "default_radius")]
    pub radius: usize,
    /// The scale lookup beside the normal one (DEFOM-Stereo); none in RAFT-Stereo.
    #[serde(default)]
    pub scale_lookup: Option<ScaleLookup>,
    /// IGEV-Stereo's geometry encoding volume, looked up instead of the all-pairs pyramid alone
    /// ([`Correlation::Geometry`]); none in RAFT-Stereo.
    #[serde(default)]
    pub geometry: Option<GeometryVolume>,
}

/// DEFOM-Stereo's scale lookup: the volume's level 0 sampled at `x + s·f + dx` for each scale `s`
/// of `scales` and `dx = -radius..=radius`, `f` the current x flow (`-disparity`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleLookup {
    /// The scales (`scale_list`: 0.125, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 2).
    #[serde(default = "default_scales")]
    pub scales: Vec<f32>,
    /// The radius around each (`scale_corr_radius`, 2).
    #[serde(default = "default_scale_radius")]
    pub radius: usize,
}

fn default_scales() -> Vec<f32> {
    vec![0.125, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0]
}
fn default_scale_radius() -> usize {
    2
}

impl Default for ScaleLookup {
    fn default() -> Self {
        Self { scales: default_scales(), radius: default_scale_radius() }
    }
}

impl ScaleLookup {
    /// Channels of a lookup: `scales · (2·radius + 1)`.
    pub fn channels(&self) -> usize {
        self.scales.len() * (2 * self.radius + 1)
    }

    /// Everything wrong with the options, keys relative to its table: no scales, or a scale
    /// that is not a positive finite number.
    pub fn problems(&self) -> Vec<Problem> {
        if self.scales.is_empty() {
            return vec![Problem::new("scales", "must list at least one scale")];
        }
        match self.scales.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            Some(s) => vec![Problem::new("scales", format!("{s} is not a positive number"))],
            None => Vec::new(),
        }
    }
}

fn default_levels() -> usize {
    4
}
fn default_radius() -> usize {
    4
}

impl Default for CorrelationConfig {
    fn default() -> Self {
        Self {
            implementation: CorrelationImplementation::Reg,
            levels: 4,
            radius: 4,
            scale_lookup: None,
            geometry: None,
        }
    }
}

impl CorrelationConfig {
    /// Everything wrong with the options, keys relative to the correlation table (`levels`
    /// must be at least 1; the scale lookup's problems under `scale_lookup`).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        if self.levels == 0 {
            problems.push(Problem::new("levels", "must be at least 1"));
        }
        if let Some(scale) = &self.scale_lookup {
            problems.extend(scale.problems().into_iter().map(|p| p.within("scale_lookup")));
        }
        if let Some(geometry) = &self.geometry {
            problems.extend(geometry.problems().into_iter().map(|p| p.within("geometry")));
            if self.scale_lookup.is_some() {
                problems.push(Problem::new("geometry", "the geometry volume has no scale lookup: remove scale_lookup"));
            }
        }
        problems
    }

    /// Channels of a lookup: `levels · (2·radius + 1)`, and with the geometry volume
    /// `levels · (groups + 1) · (2·radius + 1)`.
    pub fn channels(&self) -> usize {
        let per_tap = self.geometry.as_ref().map_or(1, |g| g.groups + 1);
        self.levels * per_tap * (2 * self.radius + 1)
    }

    /// Builds the volume of `fmap1` against `fmap2` (`[N, C, H, W]` each).
    pub fn build(&self, fmap1: Tensor<4>, fmap2: Tensor<4>) -> Correlation {
        self.build_with(self.implementation, fmap1, fmap2)
    }

    /// Builds the volume with an explicit implementation.
    pub fn build_with(
        &self,
        implementation: CorrelationImplementation,
        fmap1: Tensor<4>,
        fmap2: Tensor<4>,
    ) -> Correlation {
        match implementation {
            CorrelationImplementation::Reg => {
                Correlation::Reg(CorrelationPyramid::new(fmap1, fmap2, self.levels, self.radius))
            }
            CorrelationImplementation::Alt => {
                Correlation::Alt(OnTheFlyCorrelation::new(fmap1, fmap2, self.levels, self.radius))
            }
        }
    }

    /// Bytes the materialised pyramid of a `[N, C, H, W]` feature pair would hold (float32).
    pub fn pyramid_bytes(&self, n: usize, h: usize, w: usize) -> usize {
        let mut per_row = 0;
        let mut width = w;
        for _ in 0..=self.levels {
            per_row += width;
            width /= 2;
        }
        4 * n * h * w * per_row
    }
}

/// A built volume of either implementation.
#[derive(Debug, Clone)]
pub enum Correlation {
    /// Materialised pyramid.
    Reg(CorrelationPyramid),
    /// On-the-fly.
    Alt(OnTheFlyCorrelation),
    /// IGEV-Stereo's geometry volume and all-pairs correlation.
    Geometry(CombinedGeometryVolume),
}

impl Correlation {
    /// The scale lookup ([`ScaleLookup`]): for each scale `s`, level 0 sampled around
    /// `coords0 + s·flow_x` with `lookup.radius`, the scales' samples side by side.
    ///
    /// # Shapes
    /// - `coords0`, `flow_x`: `[N, 1, H, W]`; output `[N, scales · (2·radius + 1), H, W]`,
    ///   scale-major, offsets ascending
    pub fn scale_lookup(&self, coords0: Tensor<4>, flow_x: Tensor<4>, lookup: &ScaleLookup) -> Tensor<4> {
        let samples = lookup
            .scales
            .iter()
            .map(|&s| {
                let at = coords0.clone() + flow_x.clone().mul_scalar(s);
                match self {
                    Self::Reg(c) => c.lookup_levels(at, 1, lookup.radius),
                    Self::Alt(c) => c.lookup_levels(at, 1, lookup.radius),
                    Self::Geometry(c) => c.lookup(coords0.clone(), flow_x.clone().mul_scalar(-s)),
                }
            })
            .collect();
        Tensor::cat(samples, 1)
    }
}

impl Correlation {
    /// The lookup at the positive disparity `disparity` of the pixels at columns `coords0`:
    /// the geometry volume reads the disparity itself, the others the match `coords0 -
    /// disparity`.
    ///
    /// # Shapes
    /// - `coords0`, `disparity`: `[N, 1, H, W]`
    pub fn lookup_disparity(&self, coords0: Tensor<4>, disparity: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Geometry(c) => c.lookup(coords0, disparity),
            _ => self.lookup(coords0 - disparity),
        }
    }
}

impl CostVolume for CorrelationPyramid {
    fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4> {
        CorrelationPyramid::lookup(self, coords_x)
    }
}

impl CostVolume for OnTheFlyCorrelation {
    fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4> {
        OnTheFlyCorrelation::lookup(self, coords_x)
    }
}

impl CostVolume for Correlation {
    fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Reg(c) => c.lookup(coords_x),
            Self::Alt(c) => c.lookup(coords_x),
            Self::Geometry(c) => {
                // The disparity of a match: each pixel's column less the match's.
                let [n, _, h, w] = coords_x.dims();
                let columns = Tensor::<1, burn::tensor::Int>::arange(0..w as i64, &coords_x.device()).float();
                let coords0 = columns.reshape([1, 1, 1, w]).expand([n, 1, h, w]);
                c.lookup(coords0.clone(), coords0 - coords_x)
            }
        }
    }
}

#[cfg(test)]
mod tests;
