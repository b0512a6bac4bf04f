//! Properties of the correlation stage on small random features: its configuration's choices
//! and the scale lookup. The lookups themselves are tested on every path in the kernels crate
//! (`ops/lookup/tests.rs`).

use burn::tensor::Tensor;
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, max_abs_diff, to_vec};
use proptest::prelude::*;

use dgstereo_kernels::{Path, with_path};

use crate::{Correlation, CorrelationConfig, CorrelationImplementation, CostVolume, ScaleLookup};

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
}

/// An Alt configuration builds the on-the-fly volume, which picks its host kernel on the CPU.
#[test]
fn an_alt_configuration_builds_the_on_the_fly_volume() {
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
