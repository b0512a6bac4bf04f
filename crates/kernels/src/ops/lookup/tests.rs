//! The lookups on every path of the dispatch against burn's tensor operations (the stock path)
//! and against the dot products written out, on small deterministic features.

use burn::tensor::{Device, Tensor};
use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

use super::{CorrelationPyramid, OnTheFlyCorrelation};
use crate::dispatch::{Op, Path, path, with_path};

/// Cases of each property test, per path.
const CASES: u32 = 12;

/// The pyramid stored and looked up on `pinned` (where the device allows it).
fn pyramid(pinned: Path, f1: Tensor<4>, f2: Tensor<4>, levels: usize, radius: usize) -> CorrelationPyramid {
    with_path(pinned, || CorrelationPyramid::new(f1, f2, levels, radius))
}

/// The on-the-fly volume stored and looked up on `pinned`.
fn on_the_fly(pinned: Path, f1: Tensor<4>, f2: Tensor<4>, levels: usize, radius: usize) -> OnTheFlyCorrelation {
    with_path(pinned, || OnTheFlyCorrelation::new(f1, f2, levels, radius))
}

/// Deterministic pseudo-random features of unit scale.
pub(super) fn features(n: usize, c: usize, h: usize, w: usize, seed: u64) -> Tensor<4> {
    let v: Vec<f32> =
        (0..n * c * h * w).map(|i| (((i as u64 + 1) * 2654435761 + seed * 97) % 1000) as f32 / 500.0 - 1.0).collect();
    from_vec(v, [n, c, h, w], &Device::flex())
}

/// `[N, 1, H, W]` match positions: each pixel's column plus `shift` times a fraction in
/// `[0, 1)`, so fractional and (for large `shift`) outside the row.
fn coords(n: usize, h: usize, w: usize, shift: f32) -> Tensor<4> {
    let x: Vec<f32> = (0..n * h * w).map(|i| (i % w) as f32 + shift * ((i * 7 % 11) as f32 / 11.0)).collect();
    from_vec(x, [n, 1, h, w], &Device::flex())
}

fn max_abs(t: Tensor<4>) -> f32 {
    to_vec(t).iter().fold(0f32, |m, v| m.max(v.abs()))
}

/// The scale of the lookups' rounding: the largest sum of absolute products `Σ_c |f1|·|f2| /
/// √C` over every pair of a row's pixels (the correlation before any bilinear weight). Measured
/// against the largest output instead, a case whose every lookup fell near or past the row's end
/// (`w1 = 5, w2 = 33, c = 30, radius 0, shift -35`: largest output 1.1e-3, a difference of
/// 3.3e-8) failed the suite once.
///
/// # Shapes
/// - `f1`: `[N, C, H, W1]`; `f2`: `[N, C, H, W2]`
fn correlation_scale(f1: Tensor<4>, f2: Tensor<4>) -> f32 {
    let c = f1.dims()[1] as f32;
    let sums = f1.abs().permute([0, 2, 3, 1]).matmul(f2.abs().permute([0, 2, 1, 3]));
    max_abs(sums) / c.sqrt()
}

/// Runs `property` on [`CASES`] cases of `strategy`, failing with proptest's shrunk case.
fn check<S: Strategy>(strategy: S, property: impl Fn(S::Value) -> Result<(), TestCaseError>) {
    let mut runner = TestRunner::new(Config::with_cases(CASES));
    if let Err(failure) = runner.run(&strategy, property) {
        panic!("{failure}");
    }
}

crate::test_paths!(
    /// The pyramid's stored levels (within 1e-6) and its lookups (within 1e-5) are the stock
    /// path's: batches, odd widths, levels pooled down to width 1 or 0, fractional positions in
    /// and out of the row.
    fn the_pyramid_matches_the_stock_lookup(pinned) {
        let cases = (1usize..40, 1usize..4, 1usize..3, 1usize..7, 0usize..5, 0u64..1000, -50f32..50.0);
        check(cases, |(w, h, n, levels, radius, seed, shift)| {
            let (f1, f2) = (features(n, 16, h, w, seed), features(n, 16, h, w, seed + 1));
            let stock = pyramid(Path::Stock, f1.clone(), f2.clone(), levels, radius);
            let got = pyramid(pinned, f1, f2, levels, radius);
            for (a, b) in stock.levels().into_iter().zip(got.levels()) {
                prop_assert_eq!(a.dims(), b.dims());
                if a.dims()[1] > 0 {
                    prop_assert!(max_abs_diff(a, b) <= 1e-6);
                }
            }
            let x = coords(n, h, w, shift);
            let (a, b) = (stock.lookup(x.clone()), got.lookup(x));
            prop_assert_eq!(a.dims(), [n, levels * (2 * radius + 1), h, w]);
            prop_assert_eq!(a.dims(), b.dims());
            let diff = max_abs_diff(a, b);
            prop_assert!(diff <= 1e-5, "{:?}: differ by {}", pinned, diff);
            Ok(())
        });
    }
);

crate::test_paths!(
    /// The on-the-fly lookups are the stock path's within 1e-5 of the correlation's scale
    /// ([`correlation_scale`]): odd channel counts (the dot product's remainder), different left
    /// and right widths, fractional positions in and out of the row, levels pooled down to
    /// width 1 or 0.
    fn on_the_fly_matches_the_stock_lookup(pinned) {
        let cases = (1usize..40, 1usize..40, 1usize..4, 1usize..3, 1usize..40, 1usize..7, 0usize..5, 0u64..1000, -50f32..50.0);
        check(cases, |(w1, w2, h, n, c, levels, radius, seed, shift)| {
            let (f1, f2) = (features(n, c, h, w1, seed), features(n, c, h, w2, seed + 1));
            let scale = correlation_scale(f1.clone(), f2.clone());
            let stock = on_the_fly(Path::Stock, f1.clone(), f2.clone(), levels, radius);
            let got = on_the_fly(pinned, f1, f2, levels, radius);
            let x = coords(n, h, w1, shift);
            let (a, b) = (stock.lookup(x.clone()), got.lookup(x));
            prop_assert_eq!(a.dims(), [n, levels * (2 * radius + 1), h, w1]);
            prop_assert_eq!(a.dims(), b.dims());
            let (diff, scale) = (max_abs_diff(a.clone(), b), max_abs(a).max(scale));
            prop_assert!(diff <= 1e-5 * scale, "{:?}: differ by {} (scale {})", pinned, diff, scale);
            Ok(())
        });
    }
);

crate::test_paths!(
    /// The on-the-fly dot products and the materialised pyramid look up the same values.
    fn on_the_fly_matches_the_pyramid(pinned) {
        let cases = (1usize..40, 1usize..3, 1usize..3, 1usize..6, 0usize..5, 0u64..1000, -50f32..50.0);
        check(cases, |(w, h, n, levels, radius, seed, shift)| {
            let (f1, f2) = (features(n, 16, h, w, seed), features(n, 16, h, w, seed + 1));
            let scale = correlation_scale(f1.clone(), f2.clone());
            let x = coords(n, h, w, shift);
            let a = pyramid(pinned, f1.clone(), f2.clone(), levels, radius).lookup(x.clone());
            let b = on_the_fly(pinned, f1, f2, levels, radius).lookup(x);
            prop_assert_eq!(a.dims(), b.dims());
            let (diff, scale) = (max_abs_diff(a.clone(), b), max_abs(a).max(scale));
            prop_assert!(diff <= 1e-5 * scale, "{:?}: differ by {} (scale {})", pinned, diff, scale);
            Ok(())
        });
    }
);

crate::test_paths!(
    /// Levels pooled to width 1 (still sampled) and 0 (all zero) match the stock path, in a batch
    /// of two with positions on, between, left and right of the columns (the gathered lookup's
    /// bound for an empty level must keep every sample there zero).
    fn exhausted_levels_are_sampled_or_zero(pinned) {
        let (n, c, h, w, levels, radius) = (2, 8, 2, 5, 4, 2); // widths 5, 2, 1, 0
        let (f1, f2) = (features(n, c, h, w, 3), features(n, c, h, w, 4));
        let pattern = [0.0, 0.5, -0.5, 4.75, 1e3, -7.25, 2.0, 3.5, -1e3, 1.25, -4.0, 1.0];
        let x: Vec<f32> = (0..n * h * w).map(|i| pattern[i % pattern.len()]).collect();
        let x = from_vec(x, [n, 1, h, w], &Device::flex());
        let k = 2 * radius + 1;
        let volumes = [
            ("pyramid", pyramid(Path::Stock, f1.clone(), f2.clone(), levels, radius).lookup(x.clone()),
                pyramid(pinned, f1.clone(), f2.clone(), levels, radius).lookup(x.clone())),
            ("on the fly", on_the_fly(Path::Stock, f1.clone(), f2.clone(), levels, radius).lookup(x.clone()),
                on_the_fly(pinned, f1, f2, levels, radius).lookup(x)),
        ];
        for (name, a, b) in volumes {
            let (diff, scale) = (max_abs_diff(a.clone(), b.clone()), max_abs(a));
            assert!(diff <= 1e-5 * scale, "{name} on {pinned:?}: differ by {diff} (largest {scale})");
            let out = to_vec(b);
            let plane = h * w;
            let level = |b: usize, l: usize| out[(b * levels + l) * k * plane..(b * levels + l + 1) * k * plane].to_vec();
            for b in 0..n {
                assert!(level(b, 2).iter().any(|v| *v != 0.0), "{name}: the width-1 level is sampled (batch {b})");
                assert!(level(b, 3).iter().all(|v| *v == 0.0), "{name}: the width-0 level is zero (batch {b})");
            }
        }
    }
);

crate::test_paths!(
    /// At integer positions, level 0 of either lookup is the plain dot product of the features
    /// over `√C` (zero outside the row).
    fn level_zero_is_the_dot_product(pinned) {
        let (n, c, h, w, r, disparity) = (1, 8, 2, 12, 3, 2);
        let (f1, f2) = (features(n, c, h, w, 7), features(n, c, h, w, 8));
        let x: Vec<f32> = (0..h * w).map(|i| (i % w) as f32 - disparity as f32).collect();
        let x = from_vec(x, [n, 1, h, w], &Device::flex());
        let (a, b) = (to_vec(f1.clone()), to_vec(f2.clone()));
        let looked_up = [
            to_vec(pyramid(pinned, f1.clone(), f2.clone(), 2, r).lookup(x.clone())),
            to_vec(on_the_fly(pinned, f1, f2, 2, r).lookup(x)),
        ];
        for out in looked_up {
            for y in 0..h {
                for x in 0..w {
                    for (t, dx) in (-(r as i64)..=r as i64).enumerate() {
                        let x2 = x as i64 - disparity + dx;
                        let expected = if (0..w as i64).contains(&x2) {
                            (0..c).map(|ch| a[(ch * h + y) * w + x] * b[(ch * h + y) * w + x2 as usize]).sum::<f32>()
                                / (c as f32).sqrt()
                        } else {
                            0.0
                        };
                        let got = out[(t * h + y) * w + x];
                        assert!((got - expected).abs() < 1e-5, "{pinned:?} y {y} x {x} dx {dx}: {got} vs {expected}");
                    }
                }
            }
        }
    }
);

/// Inference on the CPU picks the host kernels; an autodiff device keeps the differentiable
/// stock ones, through which gradients reach both feature maps.
#[test]
fn the_lookups_follow_the_device() {
    let device = Device::flex();
    assert_eq!(path(&device, Op::Lookup), Path::Host);
    assert_eq!(path(&device.clone().autodiff(), Op::Lookup), Path::Stock);
    let (n, c, h, w) = (1, 4, 2, 6);
    let (f1, f2) = (features(n, c, h, w, 1), features(n, c, h, w, 2));
    assert_eq!(CorrelationPyramid::new(f1.clone(), f2.clone(), 2, 1).path(), Path::Host);
    assert_eq!(OnTheFlyCorrelation::new(f1.clone(), f2.clone(), 2, 1).path(), Path::Host);
    assert_eq!(pyramid(Path::Gpu, f1, f2, 2, 1).path(), Path::Gpu);

    let ad = device.autodiff();
    let f1 = from_vec(to_vec(features(n, c, h, w, 1)), [n, c, h, w], &ad).require_grad();
    let f2 = from_vec(to_vec(features(n, c, h, w, 2)), [n, c, h, w], &ad).require_grad();
    let alt = OnTheFlyCorrelation::new(f1.clone(), f2.clone(), 2, 1);
    assert_eq!(alt.path(), Path::Stock);
    let x: Vec<f32> = (0..n * h * w).map(|i| (i % w) as f32 - 0.5).collect();
    let grads = alt.lookup(from_vec(x, [n, 1, h, w], &ad)).sum().backward();
    for (name, f) in [("fmap1", f1), ("fmap2", f2)] {
        let grad = f.grad(&grads).unwrap_or_else(|| panic!("{name} gets a gradient"));
        assert!(to_vec(grad).iter().any(|g| *g != 0.0), "{name}'s gradient is not all zero");
    }
}
