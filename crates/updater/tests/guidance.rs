//! Properties of the GRU's depth guidance: the gradient feature (and the depth variant) ignore the
//! unknown scale and shift of a relative depth prior, and point along the depth gradient.

use burn::tensor::{Device, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};
use dgstereo_updater::{GuidanceKind, gradient_feature};
use proptest::prelude::*;

/// A smooth random depth map `[1, 1, h, w]`: a sum of a few random waves plus an offset, so that
/// the gradient is rarely close to zero.
fn smooth_depth(h: usize, w: usize, waves: &[(f32, f32, f32, f32)], device: &Device) -> Tensor<4> {
    let values = (0..h * w)
        .map(|i| {
            let (y, x) = ((i / w) as f32, (i % w) as f32);
            5.0 + 0.3 * x + waves.iter().map(|(a, fx, fy, p)| a * (fx * x + fy * y + p).sin()).sum::<f32>()
        })
        .collect();
    from_vec(values, [1, 1, h, w], device)
}

fn ramp(h: usize, w: usize, slope_x: f32, slope_y: f32, device: &Device) -> Tensor<4> {
    let values = (0..h * w).map(|i| 10.0 + slope_x * (i % w) as f32 + slope_y * (i / w) as f32).collect();
    from_vec(values, [1, 1, h, w], device)
}

fn channel(feature: &Tensor<4>, c: usize) -> Vec<f32> {
    let [n, _, h, w] = feature.dims();
    to_vec(feature.clone().slice([0..n, c..c + 1, 0..h, 0..w]))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `feature(a·D + b) = feature(D)` for `a > 0`: instance normalisation comes first. (Up to
    /// its epsilon, 1e-5, against the variance of the resized depth: scales are kept where that
    /// variance stays well above it.)
    #[test]
    fn guidance_is_invariant_to_positive_affine_depth_changes(
        h in 8usize..24,
        w in 8usize..32,
        grid_h in 2usize..8,
        grid_w in 2usize..8,
        waves in proptest::collection::vec((0.2f32..2.0, -0.8f32..0.8, -0.8f32..0.8, 0.0f32..6.3), 1..4),
        scale in 0.5f32..20.0,
        shift in -50.0f32..50.0,
    ) {
        let device = default_device();
        let depth = smooth_depth(h, w, &waves, &device);
        let changed = depth.clone().mul_scalar(scale).add_scalar(shift);
        for kind in [GuidanceKind::Gradient, GuidanceKind::Depth] {
            let a = kind.feature(depth.clone(), [grid_h, grid_w]).unwrap();
            let b = kind.feature(changed.clone(), [grid_h, grid_w]).unwrap();
            prop_assert_eq!(a.dims(), [1, kind.channels(), grid_h, grid_w]);
            prop_assert!(to_vec(a.clone()).iter().all(|v| v.is_finite()));
            let diff = max_abs_diff(a, b);
            prop_assert!(diff < 2e-3, "{:?}: differ by {} (scale {}, shift {})", kind, diff, scale, shift);
        }
    }

    /// A linear ramp has one gradient direction inside the image and a constant magnitude there;
    /// everywhere the direction is a unit vector with the slope's signs.
    #[test]
    fn a_ramp_points_along_its_slope(
        h in 4usize..16,
        w in 4usize..16,
        slope_x in -3.0f32..3.0,
        slope_y in -3.0f32..3.0,
    ) {
        prop_assume!(slope_x.abs() + slope_y.abs() > 0.05);
        let device = default_device();
        let feature = gradient_feature(ramp(h, w, slope_x, slope_y, &device), [h, w]);
        let norm = (slope_x * slope_x + slope_y * slope_y).sqrt();
        let (ux, uy) = (slope_x / norm, slope_y / norm);
        let (gx, gy, magnitude) = (channel(&feature, 0), channel(&feature, 1), channel(&feature, 2));
        // Interior pixels: Sobel of a ramp is exact. Border pixels see a replicated row or column,
        // which shortens one component, so only the interior is compared for direction.
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let i = y * w + x;
                prop_assert!((gx[i] - ux).abs() < 1e-3 && (gy[i] - uy).abs() < 1e-3,
                    "({}, {}): ({}, {}) vs ({}, {})", y, x, gx[i], gy[i], ux, uy);
                let centre = (h / 2) * w + w / 2;
                prop_assert!((magnitude[i] - magnitude[centre]).abs() < 1e-3, "{} vs {}", magnitude[i], magnitude[centre]);
            }
        }
        // Everywhere: unit direction vectors (up to the epsilon) with the slope's signs.
        for i in 0..h * w {
            let length = (gx[i] * gx[i] + gy[i] * gy[i]).sqrt();
            prop_assert!((length - 1.0).abs() < 1e-3, "length {}", length);
            prop_assert!(gx[i] * slope_x >= -1e-6 && gy[i] * slope_y >= -1e-6);
        }
    }
}

#[test]
fn no_guidance_has_no_feature() {
    let device = default_device();
    let depth = ramp(8, 8, 1.0, 0.0, &device);
    assert!(GuidanceKind::None.feature(depth, [4, 4]).is_none());
    assert_eq!(GuidanceKind::None.channels(), 0);
}

#[test]
fn batch_elements_are_normalised_independently() {
    // Two images of one batch, one a scaled copy of the other: the same feature for both.
    let device = default_device();
    let a = smooth_depth(12, 16, &[(1.0, 0.3, 0.2, 0.5)], &device);
    let batch = Tensor::cat(vec![a.clone(), a.mul_scalar(7.0).add_scalar(3.0)], 0);
    let feature = gradient_feature(batch, [6, 8]);
    let first = feature.clone().slice([0..1, 0..3, 0..6, 0..8]);
    let second = feature.slice([1..2, 0..3, 0..6, 0..8]);
    assert!(max_abs_diff(first, second) < 2e-3);
}

/// `GuidanceKind::ALL` lists every kind serde accepts, once, in the enum's order, and names each
/// as TOML does: the tests and checks that draw their kinds from it see every kind.
#[test]
fn every_kind_is_listed() {
    use serde::Deserialize;
    use serde::de::value::{Error, StrDeserializer};
    let accepted = dgstereo_core::serde_names::accepted_names::<GuidanceKind>().unwrap();
    let listed: Vec<&str> = GuidanceKind::ALL.iter().map(|k| k.name()).collect();
    assert_eq!(listed, accepted);
    for kind in GuidanceKind::ALL {
        assert_eq!(GuidanceKind::deserialize(StrDeserializer::<Error>::new(kind.name())), Ok(kind));
    }
}
