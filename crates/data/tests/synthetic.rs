//! The synthetic generator: exact correspondence, determinism, speed.

mod common;

use dgstereo_data::synthetic::{DisparityField, Outline, Surface, SyntheticConfig, SyntheticScene, Texture, generate};

fn small(seed_wl: f64) -> SyntheticConfig {
    SyntheticConfig {
        min_wavelength: seed_wl,
        max_wavelength: 48.0,
        max_disparity: 24.0,
        ..SyntheticConfig::with_size(96, 64)
    }
}

#[test]
fn same_seed_same_scene_other_seed_other_scene() {
    let cfg = small(6.0);
    let a = generate(&cfg, 7);
    assert_eq!(a, generate(&cfg, 7));
    assert_ne!(a.left, generate(&cfg, 8).left);
    assert_eq!((a.left.width, a.left.height), (96, 64));
}

#[test]
fn right_view_at_the_disparity_reproduces_the_left_view_exactly() {
    let cfg = small(4.0);
    for seed in 0..4 {
        let scene = SyntheticScene::random(&cfg, seed);
        let s = scene.render();
        for &d in &s.disparity.data {
            let d = f64::from(d);
            assert!(d.is_finite() && d >= cfg.min_disparity - 1e-6 && d <= cfg.max_disparity + 1e-6, "d {d}");
        }
        let checked = common::assert_right_view_matches_left(&scene, &s, seed);
        let n = s.left.width * s.left.height;
        assert!(checked > n / 2, "seed {seed}: only {checked} of {n} pixels visible in both views");
    }
}

#[test]
fn near_scenes_draw_their_smallest_disparity_from_the_range() {
    let far = small(4.0);
    let near = SyntheticConfig { min_disparity_range: Some([8.0, 16.0]), ..far.clone() };
    let mut smallest = Vec::new();
    for seed in 0..6 {
        let scene = SyntheticScene::random(&near, seed);
        let s = scene.render();
        let low = s.disparity.data.iter().copied().fold(f32::INFINITY, f32::min);
        let high = s.disparity.data.iter().copied().fold(0f32, f32::max);
        assert!((8.0 - 1e-4..=16.0 + 0.25 * 24.0).contains(&low), "seed {seed}: smallest disparity {low}");
        assert!(high <= 24.0 + 1e-4, "seed {seed}: largest disparity {high}");
        common::assert_right_view_matches_left(&scene, &s, seed);
        // The scene's layout is drawn from the same stream as without the range.
        let plain = SyntheticScene::random(&far, seed);
        assert_eq!(scene.surfaces.len(), plain.surfaces.len(), "seed {seed}");
        assert!(low > generate(&far, seed).disparity.data.iter().copied().fold(f32::INFINITY, f32::min));
        smallest.push(low);
    }
    let spread = smallest.iter().copied().fold(0f32, f32::max) - smallest.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(spread > 1.0, "the smallest disparity does not vary across scenes: {smallest:?}");
    // A degenerate range is a fixed smallest disparity.
    let fixed = SyntheticConfig { min_disparity_range: Some([12.0, 12.0]), ..far };
    let low = generate(&fixed, 3).disparity.data.iter().copied().fold(f32::INFINITY, f32::min);
    assert!((12.0 - 1e-4..=12.0 + 0.05 * 12.0 + 1e-3).contains(&low), "smallest {low}");
}

#[test]
fn lattices_stand_in_front_with_holes_and_leave_the_other_draws_alone() {
    // A bar at u = 0..2 of a period-10 lattice: points on bars are inside, points in holes not.
    let grid = Outline::Lattice { cx: 50.0, cy: 50.0, hw: 40.0, hh: 40.0, cos: 1.0, sin: 0.0, period: 10.0, bar: 2.0 };
    assert!(grid.contains(10.5, 17.0) && grid.contains(15.0, 20.5));
    assert!(!grid.contains(15.0, 15.0) && !grid.contains(95.0, 50.0));
    let plain = SyntheticConfig { max_disparity: 40.0, ..small(4.0) };
    let with = SyntheticConfig { lattice_prob: 1.0, ..plain.clone() };
    let mut occluded = [0usize; 2];
    for seed in 0..4 {
        let (a, b) = (SyntheticScene::random(&plain, seed), SyntheticScene::random(&with, seed));
        // The lattice is one more surface after the same ones.
        assert_eq!(b.surfaces.len(), a.surfaces.len() + 1, "seed {seed}");
        assert_eq!(b.surfaces[..a.surfaces.len()], a.surfaces[..], "seed {seed}");
        let Outline::Lattice { period, bar, .. } = b.surfaces.last().unwrap().outline else {
            panic!("seed {seed}: the last surface is not a lattice")
        };
        assert!(bar >= 1.5 && bar < period, "seed {seed}: bar {bar}, period {period}");
        let (ra, rb) = (a.render(), b.render());
        common::assert_right_view_matches_left(&b, &rb, seed);
        occluded[0] += ra.occlusion.data.iter().filter(|v| **v).count();
        occluded[1] += rb.occlusion.data.iter().filter(|v| **v).count();
    }
    assert!(occluded[1] > occluded[0], "the lattices add no occlusions: {occluded:?}");
    // The default draws none.
    assert_eq!(SyntheticConfig::default().lattice_prob, 0.0);
}

#[test]
fn warping_the_right_image_by_the_left_disparity_reproduces_the_left_image() {
    // Smooth textures (wavelengths >= 16 px): linear interpolation error stays small.
    let cfg = small(16.0);
    for seed in 10..13 {
        let s = generate(&cfg, seed);
        let errors = common::warping_errors(&s);
        let n = errors.len() / 3;
        let sum: f64 = errors.iter().map(|e| f64::from(*e)).sum();
        let worst = errors.iter().copied().fold(0f32, f32::max);
        let mean = sum / (3 * n) as f64;
        assert!(n > 2000, "seed {seed}: {n} pixels compared");
        assert!(mean < 0.5 && worst < 6.0, "seed {seed}: mean {mean}, worst {worst}");
    }
}

#[test]
fn slanted_plane_disparity_is_exact_and_occludes_the_background() {
    let tex = |v: f64| Texture { base: [v; 3], gratings: vec![], noise_cell: 0.0, noise_amp: [0.0; 3], noise_seed: 0 };
    let plane = DisparityField { c: 10.0, a: 0.1, b: -0.05, kx: 0.0, ky: 0.0, x0: 20.0, y0: 10.0 };
    let fg = Surface::new(
        Outline::Rect { cx: 20.0, cy: 10.0, hw: 6.0, hh: 5.0, cos: 1.0, sin: 0.0 },
        plane.clone(),
        tex(200.0),
    );
    let bg = Surface::new(Outline::Everything, DisparityField::constant(2.0), tex(50.0));
    let scene = SyntheticScene { width: 40, height: 20, surfaces: vec![bg, fg] };
    let s = scene.render();
    for y in 0..20 {
        for x in 0..40 {
            let inside = (x as f64 - 20.0).abs() <= 6.0 && (y as f64 - 10.0).abs() <= 5.0;
            let want = if inside { plane.at(x as f64, y as f64) as f32 } else { 2.0 };
            assert!((s.disparity.get(x, y) - want).abs() < 1e-5);
            assert_eq!(s.left.get(x, y)[0], if inside { 200.0 } else { 50.0 });
        }
    }
    // At y = 10 the plane spans left x 14..=26 with d 9.4..10.6, i.e. right x 4.6..15.4, so
    // the background (d = 2) at left x 7..=13 (right x 5..=11) is hidden; x 6 and 27 are not.
    for x in 7..=13 {
        assert!(s.occlusion.get(x, 10), "x {x}");
    }
    for x in [6, 14, 20, 26, 27] {
        assert!(!s.occlusion.get(x, 10), "x {x}");
    }
    // Out of the right frame at the left border.
    assert!(s.occlusion.get(0, 0) && s.occlusion.get(1, 0) && !s.occlusion.get(2, 0));
    // Right-view disparity: the plane seen at right x = 10 (left x = 10 + d).
    let d = s.disparity_right.get(10, 10);
    assert!((plane.at(10.0 + f64::from(d), 10.0) as f32 - d).abs() < 1e-4);
}

#[test]
fn curved_patch_right_solution_is_consistent() {
    let f = DisparityField { c: 20.0, a: 0.05, b: 0.02, kx: 0.004, ky: -0.003, x0: 50.0, y0: 30.0 };
    for xl in [30.0, 45.0, 50.0, 61.5, 70.0] {
        for y in [20.0, 30.0, 41.0] {
            let xr = xl - f.at(xl, y);
            let back = f.left_x_from_right(xr, y).unwrap();
            assert!((back - xl).abs() < 1e-9, "{xl} {y} -> {back}");
        }
    }
}

#[test]
fn generator_is_fast_and_covers_all_kinds() {
    let cfg = SyntheticConfig::with_size(320, 240);
    let t = std::time::Instant::now();
    let s = generate(&cfg, 3);
    let el = t.elapsed();
    assert!(el.as_secs_f64() < 2.0, "320x240 took {el:?}");
    let occ = s.occlusion.count() as f64 / (320.0 * 240.0);
    assert!(occ > 0.0 && occ < 0.5, "occluded fraction {occ}");
    assert!(s.left.data.iter().all(|v| (0.0..=255.0).contains(v)));
    // Over a few seeds every kind of surface appears, including thin bars.
    let mut thin = false;
    let mut curved = false;
    for seed in 0..10 {
        for srf in &SyntheticScene::random(&cfg, seed).surfaces {
            thin |= matches!(srf.outline, Outline::Rect { hw, .. } if hw < 4.0);
            curved |= srf.field.kx != 0.0 || srf.field.ky != 0.0;
        }
    }
    assert!(thin && curved);
}
