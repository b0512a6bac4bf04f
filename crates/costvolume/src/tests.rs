//! Properties of the correlation stage on small random features.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};
use proptest::prelude::*;

use dgstereo_kernels::{Op, Path, path, with_path};

use crate::{
    Correlation, CorrelationConfig, CorrelationImplementation, CorrelationPyramid, CostVolume, OnTheFlyCorrelation,
    ScaleLookup,
};

/// The pyramid stored and looked up on `pinned` (where the device allows it).
fn pyramid(pinned: Path, f1: Tensor<4>, f2: Tensor<4>, levels: usize, radius: usize) -> CorrelationPyramid {
    with_path(pinned, || CorrelationPyramid::new(f1, f2, levels, radius))
}

/// The on-the-fly volume stored and looked up on `pinned`.
fn on_the_fly(pinned: Path, f1: Tensor<4>, f2: Tensor<4>, levels: usize, radius: usize) -> OnTheFlyCorrelation {
    with_path(pinned, || OnTheFlyCorrelation::new(f1, f2, levels, radius))
}

fn features(n: usize, c: usize, h: usize, w: usize, seed: u64) -> Tensor<4> {
    let device = default_device();
    // Deterministic pseudo-random features of unit scale.
    let v: Vec<f32> =
        (0..n * c * h * w).map(|i| (((i as u64 + 1) * 2654435761 + seed * 97) % 1000) as f32 / 500.0 - 1.0).collect();
    from_vec(v, [n, c, h, w], &device)
}

/// `[N, 1, H, W]` match positions: each pixel's column plus `shift` times a fraction in
/// `[0, 1)`, so fractional and (for large `shift`) outside the row.
fn coords(n: usize, h: usize, w: usize, shift: f32) -> Tensor<4> {
    let x: Vec<f32> = (0..n * h * w).map(|i| (i % w) as f32 + shift * ((i * 7 % 11) as f32 / 11.0)).collect();
    from_vec(x, [n, 1, h, w], &default_device())
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

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// The host on-the-fly kernel and the stock tensor-op one agree within 1e-5 of the
    /// correlation's scale ([`correlation_scale`]): batches, odd widths and channel counts (the dot
    /// product's remainder), different left and right widths, fractional positions in and out of
    /// the row, and levels pooled down to width 1 or 0.
    #[test]
    fn host_and_stock_on_the_fly_agree(w1 in 1usize..40, w2 in 1usize..40, h in 1usize..4, n in 1usize..3, c in 1usize..40, levels in 1usize..7, radius in 0usize..5, seed in 0u64..1000, shift in -50f32..50.0) {
        let (f1, f2) = (features(n, c, h, w1, seed), features(n, c, h, w2, seed + 1));
        let scale = correlation_scale(f1.clone(), f2.clone());
        let stock = on_the_fly(Path::Stock, f1.clone(), f2.clone(), levels, radius);
        let host = on_the_fly(Path::Host, f1, f2, levels, radius);
        prop_assert_eq!(stock.path(), Path::Stock);
        prop_assert_eq!(host.path(), Path::Host);
        let x = coords(n, h, w1, shift);
        let (a, b) = (stock.lookup(x.clone()), host.lookup(x));
        prop_assert_eq!(a.dims(), [n, levels * (2 * radius + 1), h, w1]);
        prop_assert_eq!(a.dims(), b.dims());
        let (diff, scale) = (max_abs_diff(a.clone(), b), max_abs(a).max(scale));
        prop_assert!(diff <= 1e-5 * scale, "differ by {} (scale {})", diff, scale);
    }

    /// The host on-the-fly kernel agrees with the materialised pyramid, with either of its kernels.
    #[test]
    fn host_on_the_fly_and_pyramid_agree(w in 1usize..40, h in 1usize..3, n in 1usize..3, levels in 1usize..6, radius in 0usize..5, seed in 0u64..1000, shift in -50f32..50.0) {
        let c = 16;
        let (f1, f2) = (features(n, c, h, w, seed), features(n, c, h, w, seed + 1));
        let scale = correlation_scale(f1.clone(), f2.clone());
        let alt = on_the_fly(Path::Host, f1.clone(), f2.clone(), levels, radius);
        let x = coords(n, h, w, shift);
        let b = alt.lookup(x.clone());
        for kernel in [Path::Stock, Path::Host] {
            let reg = pyramid(kernel, f1.clone(), f2.clone(), levels, radius);
            let a = reg.lookup(x.clone());
            prop_assert_eq!(a.dims(), b.dims());
            let (diff, scale) = (max_abs_diff(a.clone(), b.clone()), max_abs(a).max(scale));
            prop_assert!(diff <= 1e-5 * scale, "{:?} pyramid: differ by {} (scale {})", kernel, diff, scale);
        }
    }

    /// Both implementations agree to 1e-5 (unit-scale features) anywhere, in and out of the row.
    #[test]
    fn reg_and_alt_agree(w in 3usize..40, h in 1usize..4, levels in 1usize..5, radius in 0usize..5, seed in 0u64..1000, shift in -50f32..50.0) {
        let device = default_device();
        let c = 16;
        let cfg = CorrelationConfig { implementation: CorrelationImplementation::Reg, levels, radius, scale_lookup: None, geometry: None };
        let (f1, f2) = (features(1, c, h, w, seed), features(1, c, h, w, seed + 1));
        let reg = cfg.build_with(CorrelationImplementation::Reg, f1.clone(), f2.clone());
        let alt = cfg.build_with(CorrelationImplementation::Alt, f1, f2);
        let coords: Vec<f32> = (0..h * w).map(|i| (i % w) as f32 + shift * ((i * 7 % 11) as f32 / 11.0)).collect();
        let coords = from_vec(coords, [1, 1, h, w], &device);
        let a = reg.lookup(coords.clone());
        prop_assert_eq!(a.dims(), [1, cfg.channels(), h, w]);
        let diff = max_abs_diff(a, alt.lookup(coords));
        prop_assert!(diff <= 1e-5, "differ by {}", diff);
    }

    /// The host kernel and the stock tensor-op lookup agree to 1e-5, batches and odd widths
    /// included, and so do the stored levels.
    #[test]
    fn host_and_stock_lookups_agree(w in 1usize..40, h in 1usize..4, n in 1usize..3, levels in 1usize..5, radius in 0usize..5, seed in 0u64..1000, shift in -50f32..50.0) {
        let device = default_device();
        let c = 16;
        let (f1, f2) = (features(n, c, h, w, seed), features(n, c, h, w, seed + 1));
        let stock = pyramid(Path::Stock, f1.clone(), f2.clone(), levels, radius);
        let host = pyramid(Path::Host, f1, f2, levels, radius);
        prop_assert_eq!(host.path(), Path::Host);
        for (a, b) in stock.levels().into_iter().zip(host.levels()) {
            prop_assert_eq!(a.dims(), b.dims());
            if a.dims()[1] > 0 {
                prop_assert!(max_abs_diff(a, b) <= 1e-6);
            }
        }
        let coords: Vec<f32> = (0..n * h * w).map(|i| (i % w) as f32 + shift * ((i * 7 % 11) as f32 / 11.0)).collect();
        let coords = from_vec(coords, [n, 1, h, w], &device);
        let a = stock.lookup(coords.clone());
        let b = host.lookup(coords);
        prop_assert_eq!(a.dims(), b.dims());
        let diff = max_abs_diff(a, b);
        prop_assert!(diff <= 1e-5, "differ by {}", diff);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// The gathered lookup (two gathers over all levels, GPU inference) and the stock one agree to
    /// 1e-5: batches, odd widths, levels pooled down to width 1 or 0, positions in and out of the
    /// row.
    #[test]
    fn gathered_and_stock_lookups_agree(w in 1usize..40, h in 1usize..4, n in 1usize..3, levels in 1usize..7, radius in 0usize..5, seed in 0u64..1000, shift in -50f32..50.0) {
        let c = 16;
        let (f1, f2) = (features(n, c, h, w, seed), features(n, c, h, w, seed + 1));
        let stock = pyramid(Path::Stock, f1.clone(), f2.clone(), levels, radius);
        let gathered = pyramid(Path::Gpu, f1, f2, levels, radius);
        let coords = coords(n, h, w, shift);
        let a = stock.lookup(coords.clone());
        let b = gathered.lookup(coords);
        prop_assert_eq!(a.dims(), b.dims());
        let diff = max_abs_diff(a, b);
        prop_assert!(diff <= 1e-5, "differ by {}", diff);
    }
}

/// Levels pooled down to width 0 with integer positions at and around their (empty) rows: the
/// gathered lookup's bound for an empty level must keep every sample there zero.
#[test]
fn gathered_lookup_of_empty_levels_is_zero() {
    let (n, c, h, w, levels, radius) = (1, 8, 1, 3, 4, 2);
    let (f1, f2) = (features(n, c, h, w, 3), features(n, c, h, w, 4));
    let stock = pyramid(Path::Stock, f1.clone(), f2.clone(), levels, radius);
    let gathered = pyramid(Path::Gpu, f1, f2, levels, radius);
    for x in [-4.0f32, -1.0, 0.0, 1.0, 2.0, 4.0] {
        let coords = from_vec(vec![x; n * h * w], [n, 1, h, w], &default_device());
        let diff = max_abs_diff(stock.lookup(coords.clone()), gathered.lookup(coords));
        assert!(diff <= 1e-6, "x = {x}: differ by {diff}");
    }
}

/// Inference on the CPU picks the host kernel; an autodiff device keeps the differentiable one.
#[test]
fn kernel_follows_the_device() {
    let device = default_device();
    assert_eq!(path(&device, Op::Lookup), Path::Host);
    assert_eq!(path(&device.clone().autodiff(), Op::Lookup), Path::Stock);
    let (f1, f2) = (features(1, 4, 2, 6, 1), features(1, 4, 2, 6, 2));
    assert_eq!(CorrelationPyramid::new(f1.clone(), f2.clone(), 2, 1).path(), Path::Host);
    assert_eq!(pyramid(Path::Gpu, f1, f2, 2, 1).path(), Path::Gpu);
}

/// The on-the-fly volume picks its host kernel on the CPU and keeps the differentiable stock
/// one under autodiff, where gradients still reach both feature maps.
#[test]
fn on_the_fly_kernel_follows_the_device() {
    let (n, c, h, w) = (1, 4, 2, 6);
    let alt = CorrelationConfig {
        implementation: CorrelationImplementation::Alt,
        levels: 2,
        radius: 1,
        scale_lookup: None,
        geometry: None,
    }
    .build(features(n, c, h, w, 1), features(n, c, h, w, 2));
    let Correlation::Alt(alt) = alt else { panic!("an Alt config builds the on-the-fly volume") };
    assert_eq!(alt.path(), Path::Host);

    let ad = default_device().autodiff();
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

/// Levels pooled to width 1 (still sampled) and 0 (all zero) match the stock path, in a batch
/// of two with coordinates on, between, left and right of the columns.
#[test]
fn on_the_fly_host_kernel_on_exhausted_levels() {
    let (n, c, h, w, levels, radius) = (2, 8, 2, 5, 4, 2); // widths 5, 2, 1, 0
    let (f1, f2) = (features(n, c, h, w, 3), features(n, c, h, w, 4));
    let stock = on_the_fly(Path::Stock, f1.clone(), f2.clone(), levels, radius);
    let host = on_the_fly(Path::Host, f1, f2, levels, radius);
    let pattern = [0.0, 0.5, -0.5, 4.75, 1e3, -7.25, 2.0, 3.5, -1e3, 1.25];
    let x: Vec<f32> = (0..n * h * w).map(|i| pattern[i % pattern.len()]).collect();
    let x = from_vec(x, [n, 1, h, w], &default_device());
    let (a, b) = (stock.lookup(x.clone()), host.lookup(x));
    let (diff, scale) = (max_abs_diff(a.clone(), b.clone()), max_abs(a));
    assert!(diff <= 1e-5 * scale, "differ by {diff} (largest {scale})");
    let k = 2 * radius + 1;
    let out = to_vec(b);
    let plane = h * w;
    let level =
        |b: usize, l: usize| out[(b * levels * k + l * k) * plane..(b * levels * k + (l + 1) * k) * plane].to_vec();
    for b in 0..n {
        assert!(level(b, 2).iter().any(|v| *v != 0.0), "the width-1 level is sampled (batch {b})");
        assert!(level(b, 3).iter().all(|v| *v == 0.0), "the width-0 level is zero (batch {b})");
    }
}

/// At integer positions, level 0 of the lookup is the plain dot product of the features.
#[test]
fn lookup_at_integer_offsets_equals_direct_dot_products() {
    let device = default_device();
    let (n, c, h, w, r) = (1, 8, 2, 12, 3);
    let f1 = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
    let f2 = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
    let cfg = CorrelationConfig {
        implementation: CorrelationImplementation::Reg,
        levels: 2,
        radius: r,
        scale_lookup: None,
        geometry: None,
    };
    let disparity = 2usize;
    let coords: Vec<f32> = (0..h * w).map(|i| (i % w) as f32 - disparity as f32).collect();
    let out = to_vec(cfg.build(f1.clone(), f2.clone()).lookup(from_vec(coords, [n, 1, h, w], &device)));
    let (a, b) = (to_vec(f1), to_vec(f2));
    let k = 2 * r + 1;
    for y in 0..h {
        for x in 0..w {
            for (t, dx) in (-(r as i64)..=r as i64).enumerate() {
                let x2 = x as i64 - disparity as i64 + dx;
                let expected = if (0..w as i64).contains(&x2) {
                    (0..c).map(|ch| a[(ch * h + y) * w + x] * b[(ch * h + y) * w + x2 as usize]).sum::<f32>()
                        / (c as f32).sqrt()
                } else {
                    0.0
                };
                let got = out[(t * h + y) * w + x];
                assert!((got - expected).abs() < 1e-4, "y {y} x {x} dx {dx}: {got} vs {expected}");
            }
        }
    }
    let _ = k;
}

/// The scale lookup samples level 0 at `x + s·f + dx` for every scale, scale-major, by linear
/// interpolation of the plain dot products (zero outside the row): checked against that formula
/// written out, for both implementations on both paths, with a batch of two.
#[test]
fn scale_lookup_samples_level_zero_at_scaled_matches() {
    let device = default_device();
    let (n, c, h, w) = (2, 8, 2, 13);
    let (f1, f2) = (features(n, c, h, w, 5), features(n, c, h, w, 6));
    let lookup = ScaleLookup::default();
    let r = lookup.radius as i64;
    // Flows of either sign, fractional, some far outside the row.
    let flow: Vec<f32> = (0..n * h * w).map(|i| ((i * 5 % 17) as f32 - 6.3) * 0.9).collect();
    let coords0: Vec<f32> = (0..n * h * w).map(|i| (i % w) as f32).collect();
    let (a, b) = (to_vec(f1.clone()), to_vec(f2.clone()));
    let corr = |bi: usize, y: usize, x1: usize, x2: i64| {
        if !(0..w as i64).contains(&x2) {
            return 0.0;
        }
        let at = |v: &[f32], ch: usize, x: usize| v[((bi * c + ch) * h + y) * w + x];
        (0..c).map(|ch| at(&a, ch, x1) * at(&b, ch, x2 as usize)).sum::<f32>() / (c as f32).sqrt()
    };
    let k = 2 * lookup.radius + 1;
    let channels = lookup.channels();
    let mut expected = vec![0f32; n * channels * h * w];
    for bi in 0..n {
        for y in 0..h {
            for x in 0..w {
                let f = flow[(bi * h + y) * w + x];
                for (si, s) in lookup.scales.iter().enumerate() {
                    for (t, dx) in (-r..=r).enumerate() {
                        let p = x as f32 + f * s + dx as f32;
                        let (p0, wt) = (p.floor(), p - p.floor());
                        let v = corr(bi, y, x, p0 as i64) * (1.0 - wt) + corr(bi, y, x, p0 as i64 + 1) * wt;
                        expected[((bi * channels + si * k + t) * h + y) * w + x] = v;
                    }
                }
            }
        }
    }
    let expected = from_vec(expected, [n, channels, h, w], &device);
    for implementation in [CorrelationImplementation::Reg, CorrelationImplementation::Alt] {
        for pinned in [Path::Host, Path::Stock] {
            let cfg = CorrelationConfig {
                implementation,
                levels: 2,
                radius: 4,
                scale_lookup: Some(lookup.clone()),
                geometry: None,
            };
            let volume = with_path(pinned, || cfg.build(f1.clone(), f2.clone()));
            let out = with_path(pinned, || {
                volume.scale_lookup(
                    from_vec(coords0.clone(), [n, 1, h, w], &device),
                    from_vec(flow.clone(), [n, 1, h, w], &device),
                    &lookup,
                )
            });
            assert_eq!(out.dims(), [n, 40, h, w]);
            let diff = max_abs_diff(out, expected.clone());
            assert!(diff < 1e-5, "{implementation:?} on {pinned:?}: {diff} from the formula");
        }
    }
    assert!(ScaleLookup { scales: vec![], radius: 2 }.problems()[0].key == "scales");
    assert!(ScaleLookup { scales: vec![1.0, -0.5], radius: 2 }.problems()[0].key == "scales");
}
