//! The geometry lookup on every path of the dispatch against burn's tensor operations (the
//! stock path) and against the interpolation written out.

use burn::tensor::{Device, Tensor};
use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

use super::GeometryPyramid;
use super::tests::features;
use crate::dispatch::{Path, with_path};

/// Deterministic pseudo-random volume `[N, G, D, H, W]` of unit scale: the lookup tests'
/// features, regrouped.
fn volume([n, g, d, h, w]: [usize; 5], seed: u64) -> Tensor<5> {
    features(n * g, d, h, w, seed).reshape([n, g, d, h, w])
}

/// `[N, 1, H, W]` disparities from `low` up to `low + span`, fractional.
fn disparities(n: usize, h: usize, w: usize, low: f32, span: f32) -> Tensor<4> {
    let d: Vec<f32> = (0..n * h * w).map(|i| low + span * ((i * 7 % 13) as f32 / 13.0)).collect();
    from_vec(d, [n, 1, h, w], &Device::flex())
}

crate::test_paths!(
    /// Every level's samples are the stock path's within 1e-6: batches, groups, odd disparity
    /// counts (pooling drops the last), fractional disparities in and past both ends.
    fn the_geometry_lookup_matches_the_stock_path(pinned) {
        let cases = (1usize..3, 1usize..5, 1usize..4, 0usize..20, 1usize..4, 1usize..7, 0usize..5, 0u64..1000, -60f32..60.0);
        let mut runner = TestRunner::new(Config::with_cases(12));
        let result = runner.run(&cases, |(n, g, levels, extra, h, w, radius, seed, low)| {
            let d = (1 << (levels - 1)) + extra;
            let v = volume([n, g, d, h, w], seed);
            let stock = with_path(Path::Stock, || GeometryPyramid::new(v.clone(), levels));
            let got = with_path(pinned, || GeometryPyramid::new(v, levels));
            let at = disparities(n, h, w, low, 2.0 * d as f32);
            let (a, b) = (stock.lookup(at.clone(), radius), got.lookup(at, radius));
            prop_assert_eq!(a.len(), levels);
            for (a, b) in a.into_iter().zip(b) {
                prop_assert_eq!(a.dims(), [n, g * (2 * radius + 1), h, w]);
                prop_assert_eq!(a.dims(), b.dims());
                let diff = max_abs_diff(a, b);
                prop_assert!(diff <= 1e-6, "{:?}: differ by {}", pinned, diff);
            }
            Ok(())
        });
        if let Err(failure) = result {
            panic!("{failure}");
        }
    }
);

crate::test_paths!(
    /// A row sampled between its entries is their linear blend, and past either end it fades to
    /// zero over one step; level 1 samples the pairs' means at half the disparity.
    fn the_samples_interpolate_with_zeros_outside(pinned) {
        let row: Vec<f32> = (0..6).map(|i| (i * i) as f32).collect();
        let v = from_vec(row.clone(), [1, 1, 6, 1, 1], &Device::flex());
        let pyramid = GeometryPyramid::new(v, 2);
        assert_eq!(pyramid.path(), if pinned == Path::Host { Path::Host } else { Path::Stock });
        let at = from_vec(vec![2.5], [1, 1, 1, 1], &Device::flex());
        let sampled: Vec<Vec<f32>> = pyramid.lookup(at, 2).into_iter().map(to_vec).collect();
        let pooled: Vec<f32> = row.chunks(2).map(|p| (p[0] + p[1]) / 2.0).collect();
        for (level, (values, x)) in [(&row, 2.5f32), (&pooled, 1.25)].into_iter().enumerate() {
            let v = |i: f32| if i >= 0.0 && (i as usize) < values.len() { values[i as usize] } else { 0.0 };
            for (k, got) in sampled[level].iter().enumerate() {
                let x = x + k as f32 - 2.0;
                let (x0, t) = (x.floor(), x - x.floor());
                let expected = v(x0) * (1.0 - t) + v(x0 + 1.0) * t;
                assert!((got - expected).abs() < 1e-6, "level {level} tap {k}: {got} vs {expected}");
            }
        }
    }
);

/// Inference on the CPU samples on the host; an autodiff device keeps the stock operations,
/// through which the gradient reaches the volume.
#[test]
fn the_geometry_lookup_follows_the_device() {
    let v = volume([1, 2, 8, 2, 3], 5);
    assert_eq!(GeometryPyramid::new(v.clone(), 2).path(), Path::Host);
    let ad = Device::flex().autodiff();
    let v = from_vec(to_vec(v), [1, 2, 8, 2, 3], &ad).require_grad();
    let pyramid = GeometryPyramid::new(v.clone(), 2);
    assert_eq!(pyramid.path(), Path::Stock);
    let at = from_vec(vec![1.5, 2.25, 3.0, 0.5, 6.75, 4.0], [1, 1, 2, 3], &ad);
    let sum = pyramid.lookup(at, 1).into_iter().map(Tensor::sum).reduce(|a, b| a + b).unwrap();
    let grads = sum.backward();
    let grad = v.grad(&grads).expect("the volume gets a gradient");
    assert!(to_vec(grad).iter().any(|g| *g != 0.0), "the volume's gradient is not all zero");
}
