//! The synthetic generator's texture kinds (dead leaves, flat, low contrast, shading) and the
//! presets: exact correspondence, sharp but anti-aliased edges, reproducibility, and the default
//! path unchanged.

mod common;

use dgstereo_data::synthetic::{
    Pattern, Shading, SurfaceTexture, SyntheticConfig, SyntheticScene, TextureKind, TexturePreset, generate,
};

fn small_rich(min_wavelength: f64) -> SyntheticConfig {
    SyntheticConfig { min_wavelength, max_wavelength: 48.0, max_disparity: 24.0, ..SyntheticConfig::rich(96, 64) }
}

/// Only `kind`, on every surface, with or without shading.
fn only(kind: usize, shading_prob: f64, min_wavelength: f64) -> SyntheticConfig {
    let mut w = [0.0; 4];
    w[kind] = 1.0;
    SyntheticConfig { texture_weights: w, background_texture_weights: w, shading_prob, ..small_rich(min_wavelength) }
}

fn fnv(h: &mut u64, v: u64) {
    for b in v.to_le_bytes() {
        *h ^= u64::from(b);
        *h = h.wrapping_mul(0x100_0000_01b3);
    }
}

/// FNV-1a over the images and disparity quantised to 1/64 (robust to last-bit differences of
/// `sin` between platforms), occlusion and surface ids of four 64x48 scenes.
fn quantised_checksum(cfg: &SyntheticConfig) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for seed in 0..4 {
        let s = generate(cfg, seed);
        for v in s.left.data.iter().chain(&s.right.data).chain(&s.disparity.data) {
            fnv(&mut h, (f64::from(*v) * 64.0).round() as i64 as u64);
        }
        for o in &s.occlusion.data {
            fnv(&mut h, u64::from(*o));
        }
        for o in &s.surface_left {
            fnv(&mut h, u64::from(*o));
        }
    }
    h
}

#[test]
fn default_mix_reproduces_the_smooth_generator() {
    // Printed by this same checksum over the generator before texture kinds were added
    // (a temporary test run on the gratings-only code; its full-resolution outputs were also
    // compared byte for byte with the new code's at 320x240).
    const BEFORE_TEXTURE_KINDS: u64 = 0xf62f_4331_fe63_8bb1;
    let cfg = SyntheticConfig::with_size(64, 48);
    assert_eq!(quantised_checksum(&cfg), BEFORE_TEXTURE_KINDS);
    assert_eq!(cfg.clone().with_textures(TexturePreset::Smooth), cfg);
    assert_eq!(SyntheticConfig::rich(64, 48).with_textures(TexturePreset::Smooth), cfg);
    assert_ne!(quantised_checksum(&SyntheticConfig::rich(64, 48)), BEFORE_TEXTURE_KINDS);
}

#[test]
fn configs_without_texture_keys_load_as_the_smooth_generator() {
    let mut json = serde_json::to_value(SyntheticConfig::rich(32, 16)).unwrap();
    let map = json.as_object_mut().unwrap();
    for key in ["texture_weights", "background_texture_weights", "shading_prob"] {
        assert!(map.remove(key).is_some(), "{key}");
    }
    let cfg: SyntheticConfig = serde_json::from_value(json).unwrap();
    assert_eq!(cfg, SyntheticConfig::with_size(32, 16));
    let rich = SyntheticConfig::rich(32, 16);
    assert_eq!(serde_json::from_str::<SyntheticConfig>(&serde_json::to_string(&rich).unwrap()).unwrap(), rich);
}

#[test]
fn texture_mix_changes_the_colours_not_the_geometry() {
    let (smooth, rich) = (SyntheticConfig::with_size(96, 64), SyntheticConfig::rich(96, 64));
    let mut some_differ = false;
    for seed in 0..3 {
        let (a, b) = (generate(&smooth, seed), generate(&rich, seed));
        assert_eq!(a.disparity, b.disparity);
        assert_eq!(a.occlusion, b.occlusion);
        assert_eq!(a.surface_left, b.surface_left);
        some_differ |= a.left != b.left;
    }
    assert!(some_differ);
}

#[test]
fn rich_scenes_are_deterministic_and_cover_every_kind() {
    let cfg = small_rich(4.0);
    let a = generate(&cfg, 7);
    assert_eq!(a, generate(&cfg, 7));
    assert_ne!(a.left, generate(&cfg, 8).left);
    let (mut kinds, mut shaded, mut unshaded) = (Vec::new(), 0, 0);
    for seed in 0..12 {
        for s in SyntheticScene::random(&cfg, seed).surfaces {
            if !kinds.contains(&s.texture.kind) {
                kinds.push(s.texture.kind);
            }
            if s.texture.shading.is_some() { shaded += 1 } else { unshaded += 1 }
        }
    }
    for k in TextureKind::ALL {
        assert!(kinds.contains(&k), "{k:?} never drawn");
    }
    assert!(shaded > 5 && unshaded > 5, "{shaded} shaded, {unshaded} not");
}

#[test]
fn rich_right_view_at_the_disparity_reproduces_the_left_view_exactly() {
    // Dead leaves everywhere, then the rich mix; shading on every surface in the first.
    for (cfg, seeds) in [(only(1, 1.0, 4.0), 0..3), (small_rich(4.0), 3..6)] {
        for seed in seeds {
            let scene = SyntheticScene::random(&cfg, seed);
            let s = scene.render();
            let checked = common::assert_right_view_matches_left(&scene, &s, seed);
            assert!(checked > s.left.data.len() / 6, "seed {seed}: {checked} pixels visible in both views");
        }
    }
}

#[test]
fn warping_the_rich_right_image_reproduces_the_left_image_away_from_sharp_edges() {
    // As the smooth generator's warping test, but texture edges are ~1 px wide, so linear
    // interpolation misses them where the two views sample an edge at different sub-pixel
    // phases: the mean error stays small and large errors stay rare (measured: mean 0.12-0.85,
    // 0.3-2.9 % above 10 grey levels, the most with shapes down to 8 px cells).
    // Dead leaves everywhere (shaded) at three finest scales, then the rich mix.
    for (cfg, seed) in
        [(only(1, 1.0, 4.0), 10), (only(1, 1.0, 8.0), 11), (only(1, 1.0, 16.0), 12), (small_rich(4.0), 13)]
    {
        let s = generate(&cfg, seed);
        let errors = common::warping_errors(&s);
        assert!(errors.iter().all(|e| e.is_finite()));
        let n = errors.len() / 3;
        let sum: f64 = errors.iter().map(|e| f64::from(*e)).sum();
        let large = errors.iter().filter(|e| **e > 10.0).count();
        let mean = sum / (3 * n) as f64;
        let large = large as f64 / (3 * n) as f64;
        assert!(n > 1500, "seed {seed}: {n} pixels compared");
        assert!(mean < 1.5 && large < 0.06, "seed {seed}: mean {mean}, share above 10 {large}");
    }
}

/// The largest colour change between horizontal neighbours `step` pixels apart over a
/// 96x64 window of `texture`, and whether every value is finite and in 0..255.
fn max_step(texture: &SurfaceTexture, step: f64) -> (f32, bool) {
    let (mut worst, mut in_range) = (0f32, true);
    for j in 0..64 {
        let y = j as f64;
        let mut prev = texture.at(0.0, y);
        let mut x = step;
        while x < 96.0 {
            let c = texture.at(x, y);
            for k in 0..3 {
                in_range &= c[k].is_finite() && (0.0..=255.0).contains(&c[k]);
                worst = worst.max((c[k] - prev[k]).abs());
            }
            prev = c;
            x += step;
        }
    }
    (worst, in_range)
}

#[test]
fn dead_leaves_have_sharp_yet_anti_aliased_edges() {
    // Same wavelength settings; the background textures of the same seeds.
    let (smooth, leaves) = (only(0, 0.0, 8.0), only(1, 0.0, 8.0));
    let (mut smooth_px, mut leaves_px) = (0f32, 0f32);
    for seed in 0..4 {
        let a = SyntheticScene::random(&smooth, seed).surfaces.swap_remove(0).texture;
        let b = SyntheticScene::random(&leaves, seed).surfaces.swap_remove(0).texture;
        assert!(matches!(b.pattern, Pattern::DeadLeaves(_)));
        let Pattern::DeadLeaves(dl) = &b.pattern else { unreachable!() };
        let (pa, ok_a) = max_step(&a, 1.0);
        let (pb, ok_b) = max_step(&b, 1.0);
        assert!(ok_a && ok_b, "seed {seed}: values outside 0..255");
        smooth_px = smooth_px.max(pa);
        leaves_px = leaves_px.max(pb);
        // Anti-aliasing: continuous at a 1/50 px scale. A hard edge would jump by the full
        // colour difference; a smoothstep over `edge_width` moves at most 1.5 / edge_width of
        // it per pixel (twice that where two edges cross).
        let (fine, _) = max_step(&b, 0.02);
        let bound = (2.0 * 255.0 * 1.5 / dl.edge_width * 0.02) as f32;
        assert!(fine <= bound, "seed {seed}: step {fine} over 0.02 px (bound {bound})");
    }
    assert!(leaves_px > 3.0 * smooth_px, "largest 1 px step: dead leaves {leaves_px}, smooth {smooth_px}");
}

fn std_dev(texture: &SurfaceTexture) -> f64 {
    let vals: Vec<f64> = (0..64)
        .flat_map(|j| (0..96).map(move |i| (i as f64 * 1.3, j as f64 * 1.7)))
        .map(|(x, y)| {
            let c = texture.at(x, y);
            f64::from(c[0] + c[1] + c[2]) / 3.0
        })
        .collect();
    let mean = vals.iter().sum::<f64>() / vals.len() as f64;
    (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len() as f64).sqrt()
}

#[test]
fn flat_and_low_contrast_textures_are_weak() {
    for seed in 0..4 {
        let background = |kind| SyntheticScene::random(&only(kind, 0.0, 4.0), seed).surfaces.swap_remove(0).texture;
        let (full, flat, low) = (background(0), background(2), background(3));
        assert_eq!((flat.kind, low.kind), (TextureKind::Flat, TextureKind::LowContrast));
        let (s_full, s_flat, s_low) = (std_dev(&full), std_dev(&flat), std_dev(&low));
        assert!(s_flat < 2.0, "seed {seed}: flat std {s_flat}");
        assert!(s_low <= 0.35 * s_full && s_low > 0.03 * s_full, "seed {seed}: {s_low} vs {s_full}");
        assert!(s_full > 5.0, "seed {seed}: full-contrast std {s_full}");
    }
}

#[test]
fn shading_is_a_smooth_gain_within_its_range() {
    let ramp = Shading::Ramp { origin: [10.0, 0.0], dir: [1.0, 0.0], length: 20.0, from: 0.6, to: 1.2 };
    assert!((ramp.gain(10.0, 5.0) - 0.6).abs() < 1e-12 && (ramp.gain(30.0, 5.0) - 1.2).abs() < 1e-12);
    assert!((ramp.gain(20.0, -3.0) - 0.9).abs() < 1e-12 && ramp.gain(-50.0, 0.0) == 0.6);
    let radial = Shading::Radial { centre: [0.0, 0.0], radius: 10.0, centre_gain: 1.1, edge: 0.7 };
    assert!((radial.gain(0.0, 0.0) - 1.1).abs() < 1e-12 && (radial.gain(10.0, 0.0) - 0.9).abs() < 1e-12);
    // Generated shadings stay within 0.6..1.2 over their surface.
    for seed in 0..4 {
        for s in SyntheticScene::random(&only(0, 1.0, 4.0), seed).surfaces {
            let shading = s.texture.shading.expect("shading_prob 1 shades every surface");
            let [x0, x1, y0, y1] = if s.bounds[0].is_finite() { s.bounds } else { [0.0, 96.0, 0.0, 64.0] };
            for (i, j) in (0..=8).flat_map(|i| (0..=8).map(move |j| (i, j))) {
                let g = shading.gain(x0 + (x1 - x0) * f64::from(i) / 8.0, y0 + (y1 - y0) * f64::from(j) / 8.0);
                assert!((0.6..=1.2).contains(&g), "seed {seed}: gain {g}");
            }
        }
    }
}
