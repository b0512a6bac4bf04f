//! IGEV-Stereo's lookup (`Combined_Geo_Encoding_Volume`): per level, the geometry encoding
//! volume sampled around the current disparity and the all-pairs correlation of the match
//! features sampled around the match `x - d`.
//!
//! Both pyramids average-pool by 2 along their last axis (disparity, or the right view's
//! column); level `i` is sampled at `d / 2^i + dx` (geometry) and `(x - d) / 2^i + dx`
//! (correlation), `dx = -r..=r`, by linear interpolation with zeros outside, as `grid_sample`
//! with `align_corners=True` samples. The correlation is the kernels' [`CorrelationPyramid`] of
//! the left match features scaled by `sqrt(C)`: IGEV-Stereo's correlation is the plain dot
//! product, the pyramid's divides by `sqrt(C)`.
//!
//! Design decision: the correlation half takes the cost volume's implementation choice like
//! RAFT-Stereo's volume: "reg" stores the all-pairs pyramid, "alt" ([`OnTheFlyCorrelation`])
//! stores the pooled right features and takes the dot products at each lookup. Pooling the
//! volume along the right view's columns and pooling the right features are the same sums (the
//! correlation is linear in the right features), so both give the reference's lookup. The
//! geometry half has no such form: it is the 3D network's output, stored, and sampled by the
//! kernels crate's [`GeometryPyramid`] (a hand-written loop in CPU inference).

use burn::tensor::Tensor;
use dgstereo_kernels::GeometryPyramid;

use crate::{CorrelationImplementation, CorrelationPyramid, OnTheFlyCorrelation};

/// The all-pairs correlation half of the lookup, stored or on the fly.
#[derive(Debug, Clone)]
enum AllPairs {
    /// The materialised pyramid ("reg").
    Stored(CorrelationPyramid),
    /// Dot products at each lookup ("alt").
    OnTheFly(OnTheFlyCorrelation),
}

/// The two pyramids of one pass.
#[derive(Debug, Clone)]
pub struct CombinedGeometryVolume {
    /// Boxed: its host storage holds a device, which would make every `Correlation` that large.
    geometry: Box<GeometryPyramid>,
    correlation: AllPairs,
    radius: usize,
}

impl CombinedGeometryVolume {
    /// The pyramids of `levels` levels of the geometry encoding volume `volume` and of the match
    /// features `match_left` against `match_right` (stored or on the fly, as `implementation`
    /// says), looked up with `radius`.
    ///
    /// # Shapes
    /// - `match_left`, `match_right`: `[N, C, H, W]`; `volume`: `[N, G, D, H, W]`
    pub fn new(
        match_left: Tensor<4>,
        match_right: Tensor<4>,
        volume: Tensor<5>,
        levels: usize,
        radius: usize,
        implementation: CorrelationImplementation,
    ) -> Self {
        let c = match_left.dims()[1];
        let geometry = Box::new(GeometryPyramid::new(volume, levels));
        let scaled = match_left.mul_scalar((c as f32).sqrt());
        let correlation = match implementation {
            CorrelationImplementation::Reg => {
                AllPairs::Stored(CorrelationPyramid::new(scaled, match_right, levels, radius))
            }
            CorrelationImplementation::Alt => {
                AllPairs::OnTheFly(OnTheFlyCorrelation::new(scaled, match_right, levels, radius))
            }
        };
        Self { geometry, correlation, radius }
    }

    /// Channels of a lookup: per level `(G + 1) · (2r + 1)`.
    pub fn channels(&self) -> usize {
        self.geometry.levels() * (self.geometry.groups() + 1) * (2 * self.radius + 1)
    }

    /// The lookup at the disparity `disparity` of each pixel at column `coords0`: per level the
    /// geometry samples (group-major, offsets ascending) then the correlation samples.
    ///
    /// # Shapes
    /// - `coords0`, `disparity`: `[N, 1, H, W]`; output `[N, levels · (G + 1) · (2r + 1), H, W]`
    pub fn lookup(&self, coords0: Tensor<4>, disparity: Tensor<4>) -> Tensor<4> {
        let taps = 2 * self.radius + 1;
        let levels = self.geometry.levels();
        let at = coords0 - disparity.clone();
        let correlation = match &self.correlation {
            AllPairs::Stored(pyramid) => pyramid.lookup_levels(at, levels, self.radius),
            AllPairs::OnTheFly(on_the_fly) => on_the_fly.lookup_levels(at, levels, self.radius),
        };
        let mut parts = Vec::with_capacity(2 * levels);
        for (i, sampled) in self.geometry.lookup(disparity, self.radius).into_iter().enumerate() {
            parts.push(sampled);
            parts.push(correlation.clone().narrow(1, i * taps, taps));
        }
        Tensor::cat(parts, 1)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;
    use dgstereo_core::default_device;
    use dgstereo_core::tensor::{from_vec, to_vec};

    use super::*;

    /// The lookup holds, per level, the geometry samples then the correlation samples; the
    /// correlation is the plain dot product of the match features (not divided by `sqrt(C)`).
    #[test]
    fn the_lookup_joins_both_pyramids_per_level() {
        let device = default_device();
        let (n, c, g, d, h, w) = (1, 4, 2, 8, 2, 6);
        let left = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let right = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let volume = Tensor::<5>::random([n, g, d, h, w], Distribution::Normal(0.0, 1.0), &device);
        let combined = CombinedGeometryVolume::new(
            left.clone(),
            right.clone(),
            volume.clone(),
            2,
            1,
            CorrelationImplementation::Reg,
        );
        assert_eq!(combined.channels(), 2 * (g + 1) * 3);
        let coords0 = from_vec((0..n * h * w).map(|i| (i % w) as f32).collect(), [n, 1, h, w], &device);
        let disparity = Tensor::<4>::zeros([n, 1, h, w], &device);
        let out = combined.lookup(coords0, disparity);
        assert_eq!(out.dims(), [n, 18, h, w]);
        let (l, r, v, o) = (to_vec(left), to_vec(right), to_vec(volume), to_vec(out));
        // Pixel (y, x) = (1, 3), level 0, at disparity 0: the middle tap of each group is the
        // volume's disparity 0; the correlation's middle tap is <left(x), right(x)>.
        let (y, x) = (1, 3);
        let out_at = |ch: usize| o[(ch * h + y) * w + x];
        for group in 0..g {
            assert!((out_at(group * 3 + 1) - v[((group * d) * h + y) * w + x]).abs() < 1e-6);
        }
        let dot: f32 = (0..c).map(|k| l[(k * h + y) * w + x] * r[(k * h + y) * w + x]).sum();
        assert!((out_at(g * 3 + 1) - dot).abs() < 1e-4, "{} vs {dot}", out_at(g * 3 + 1));
        // Level 1's geometry middle tap at disparity 0: the mean of disparities 0 and 1.
        // Group 0: disparities 0 and 1 of the pixel.
        let pooled = (v[y * w + x] + v[(h + y) * w + x]) / 2.0;
        assert!((out_at(3 * (g + 1) + 1) - pooled).abs() < 1e-6);
    }

    /// "alt" gives the lookup "reg" gives, at fractional disparities, past both ends of the row
    /// and on an odd width (whose pooling drops the last column in both forms).
    #[test]
    fn the_on_the_fly_correlation_looks_up_what_the_stored_pyramid_holds() {
        let device = default_device();
        let (n, c, g, d, h, w) = (2, 8, 2, 12, 3, 13);
        let left = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let right = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let volume = Tensor::<5>::random([n, g, d, h, w], Distribution::Normal(0.0, 1.0), &device);
        let build = |implementation| {
            CombinedGeometryVolume::new(left.clone(), right.clone(), volume.clone(), 3, 2, implementation)
        };
        let coords0 = from_vec((0..n * h * w).map(|i| (i % w) as f32).collect(), [n, 1, h, w], &device);
        let disparity = Tensor::<4>::random([n, 1, h, w], Distribution::Uniform(-3.0, 16.0), &device);
        let stored = to_vec(build(CorrelationImplementation::Reg).lookup(coords0.clone(), disparity.clone()));
        let on_the_fly = to_vec(build(CorrelationImplementation::Alt).lookup(coords0, disparity));
        let scale = stored.iter().fold(0f32, |m, v| m.max(v.abs()));
        let worst = stored.iter().zip(&on_the_fly).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(scale > 1.0, "the lookup holds values ({scale})");
        assert!(worst <= 1e-5 * scale, "alt differs from reg by {worst} (largest value {scale})");
    }
}
