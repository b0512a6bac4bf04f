//! Properties of the correlation stage on small random features.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};
use proptest::prelude::*;

use crate::{CorrelationConfig, CorrelationImplementation, CorrelationPyramid, CostVolume, LookupKernel};

fn features(n: usize, c: usize, h: usize, w: usize, seed: u64) -> Tensor<4> {
    let device = default_device();
    // Deterministic pseudo-random features of unit scale.
    let v: Vec<f32> =
        (0..n * c * h * w).map(|i| (((i as u64 + 1) * 2654435761 + seed * 97) % 1000) as f32 / 500.0 - 1.0).collect();
    from_vec(v, [n, c, h, w], &device)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// Both implementations agree to 1e-5 (unit-scale features) anywhere, in and out of the row.
    #[test]
    fn reg_and_alt_agree(w in 3usize..40, h in 1usize..4, levels in 1usize..5, radius in 0usize..5, seed in 0u64..1000, shift in -50f32..50.0) {
        let device = default_device();
        let c = 16;
        let cfg = CorrelationConfig { implementation: CorrelationImplementation::Reg, levels, radius };
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
        let stock = CorrelationPyramid::with_kernel(f1.clone(), f2.clone(), levels, radius, LookupKernel::Stock);
        let host = CorrelationPyramid::with_kernel(f1, f2, levels, radius, LookupKernel::Host);
        prop_assert_eq!(host.kernel(), LookupKernel::Host);
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

/// Inference on the CPU picks the host kernel; an autodiff device keeps the differentiable one.
#[test]
fn kernel_follows_the_device() {
    let device = default_device();
    assert_eq!(LookupKernel::for_device(&device), LookupKernel::Host);
    assert_eq!(LookupKernel::for_device(&device.clone().autodiff()), LookupKernel::Stock);
}

/// At integer positions, level 0 of the lookup is the plain dot product of the features.
#[test]
fn lookup_at_integer_offsets_equals_direct_dot_products() {
    let device = default_device();
    let (n, c, h, w, r) = (1, 8, 2, 12, 3);
    let f1 = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
    let f2 = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
    let cfg = CorrelationConfig { implementation: CorrelationImplementation::Reg, levels: 2, radius: r };
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
