//! The dense augmentor: determinism, geometry of scaling, crop and y-jitter, eraser, colour.

use dgstereo_data::synthetic::generate;
use dgstereo_data::{AugmentConfig, DisparityMap, RgbImage, SyntheticConfig, augment};

/// Every random operation off, scale fixed at 1.
fn identity_cfg(crop: [usize; 2]) -> AugmentConfig {
    AugmentConfig {
        crop,
        min_scale: 0.0,
        max_scale: 0.0,
        stretch_prob: 0.0,
        brightness: 0.0,
        contrast: 0.0,
        saturation: [1.0, 1.0],
        hue: 0.0,
        asymmetric_color_prob: 0.0,
        eraser_prob: 0.0,
        yjitter: false,
        ..AugmentConfig::default()
    }
}

fn scene(w: usize, h: usize, wl: f64) -> dgstereo_data::SyntheticSample {
    let cfg = SyntheticConfig { min_wavelength: wl, max_disparity: 20.0, ..SyntheticConfig::with_size(w, h) };
    generate(&cfg, 42)
}

#[test]
fn deterministic_per_seed_and_sized_to_the_crop() {
    let s = scene(160, 120, 4.0);
    let cfg = AugmentConfig::with_crop(64, 96);
    let a = augment(&cfg, &s.left, &s.right, &s.disparity, Some(&s.valid), 5).unwrap();
    let b = augment(&cfg, &s.left, &s.right, &s.disparity, Some(&s.valid), 5).unwrap();
    assert!(a == b);
    let c = augment(&cfg, &s.left, &s.right, &s.disparity, Some(&s.valid), 6).unwrap();
    assert!(a.left != c.left);
    for out in [&a, &c] {
        assert_eq!((out.left.width, out.left.height), (96, 64));
        assert_eq!((out.right.width, out.right.height), (96, 64));
        assert_eq!((out.disparity.width, out.disparity.height), (96, 64));
        assert_eq!((out.disparity_nearest.width, out.disparity_nearest.height), (96, 64));
        assert_eq!(out.valid.data.len(), 96 * 64);
        assert!(out.left.data.iter().chain(&out.right.data).all(|v| (0.0..=255.0).contains(v)));
    }
}

#[test]
fn scale_is_clipped_to_fit_the_crop() {
    let s = scene(100, 80, 4.0);
    let cfg = AugmentConfig { min_scale: -1.0, max_scale: -1.0, ..AugmentConfig::with_crop(64, 64) };
    for seed in 0..5 {
        let out = augment(&cfg, &s.left, &s.right, &s.disparity, None, seed).unwrap();
        // 2^-1 is below max((64+8)/80, (64+8)/100) = 0.9.
        assert!(out.scale[0] >= 0.9 - 1e-12 && out.scale[1] >= 0.9 - 1e-12, "{:?}", out.scale);
    }
}

#[test]
fn identity_settings_give_an_exact_crop() {
    let s = scene(64, 48, 4.0);
    let out = augment(&identity_cfg([32, 40]), &s.left, &s.right, &s.disparity, None, 1).unwrap();
    assert_eq!(out.scale, [1.0, 1.0]);
    // Find the crop offset from the disparity and check every map against it.
    let mut found = false;
    'search: for y0 in 0..=16 {
        for x0 in 0..=24 {
            if s.disparity.crop(x0, y0, 40, 32).unwrap() == out.disparity {
                assert!(out.left == s.left.crop(x0, y0, 40, 32).unwrap());
                assert!(out.right == s.right.crop(x0, y0, 40, 32).unwrap());
                assert!(out.disparity_nearest == out.disparity);
                found = true;
                break 'search;
            }
        }
    }
    assert!(found);
}

#[test]
fn y_jitter_shifts_the_right_crop_by_at_most_2_rows() {
    let s = scene(64, 48, 4.0);
    let cfg = AugmentConfig { yjitter: true, ..identity_cfg([32, 40]) };
    let mut shifts = std::collections::BTreeSet::new();
    for seed in 0..40 {
        let out = augment(&cfg, &s.left, &s.right, &s.disparity, None, seed).unwrap();
        let (mut x0, mut y0) = (usize::MAX, 0);
        for y in 2..16 - 2 + 1 {
            for x in 2..24 - 2 + 1 {
                if s.left.crop(x, y, 40, 32).unwrap() == out.left {
                    (x0, y0) = (x, y);
                }
            }
        }
        assert!(x0 != usize::MAX, "left crop not found; corner must lie 2 px inside");
        let dy: Vec<i64> = (-2i64..=2)
            .filter(|d| {
                let y1 = y0 as i64 + d;
                y1 >= 0 && (y1 as usize) + 32 <= 48 && s.right.crop(x0, y1 as usize, 40, 32).unwrap() == out.right
            })
            .collect();
        assert_eq!(dy.len(), 1, "seed {seed}");
        shifts.insert(dy[0]);
    }
    assert_eq!(shifts.len(), 5, "all shifts -2..=2 occur: {shifts:?}");
}

#[test]
fn eraser_fills_boxes_of_the_right_image_with_its_mean_colour() {
    let s = scene(200, 160, 4.0);
    let cfg = AugmentConfig { eraser_prob: 1.0, ..identity_cfg([150, 190]) };
    let mean: Vec<f32> = (0..3).map(|c| s.right.plane(c).iter().sum::<f32>() / (200.0 * 160.0)).collect();
    let mut erased_any = false;
    for seed in 0..6 {
        let out = augment(&cfg, &s.left, &s.right, &s.disparity, None, seed).unwrap();
        // The crop offset, from the untouched left image.
        let mut at = None;
        for y in 0..=10 {
            for x in 0..=10 {
                if s.left.crop(x, y, 190, 150).unwrap() == out.left {
                    at = Some((x, y));
                }
            }
        }
        let (x0, y0) = at.expect("left is an exact crop");
        let orig = s.right.crop(x0, y0, 190, 150).unwrap();
        for y in 0..150 {
            for x in 0..190 {
                let (a, b) = (out.right.get(x, y), orig.get(x, y));
                if a != b {
                    erased_any = true;
                    for c in 0..3 {
                        assert!((a[c] - mean[c]).abs() < 1e-2, "{a:?} vs mean {mean:?}");
                    }
                }
            }
        }
    }
    assert!(erased_any);
}

#[test]
fn scaled_disparity_still_maps_left_to_right() {
    // Smooth textures; colour, eraser and y-jitter off; scale 2^U(-0.2, 0.4) with stretch.
    let s = scene(160, 120, 16.0);
    let cfg = AugmentConfig { min_scale: -0.2, max_scale: 0.4, stretch_prob: 1.0, ..identity_cfg([80, 120]) };
    for seed in 0..3 {
        let out = augment(&cfg, &s.left, &s.right, &s.disparity, None, seed).unwrap();
        let [sx, _] = out.scale;
        // Nearest values are input values times sx.
        let scaled: Vec<f32> = s.disparity.data.iter().map(|d| d * sx as f32).collect();
        assert!(out.disparity_nearest.data.iter().all(|d| scaled.contains(d)));
        let (mut n, mut err) = (0, 0f64);
        let w = out.left.width;
        for y in 0..out.left.height {
            for x in 0..w {
                let (dl, dn) = (out.disparity.get(x, y), out.disparity_nearest.get(x, y));
                let xr = x as f32 - dl;
                if (dl - dn).abs() > 0.05 * sx as f32 || xr < 1.0 {
                    continue; // near a depth edge or out of frame
                }
                let x0 = xr.floor() as usize;
                let t = xr - x0 as f32;
                let (a, b) = (out.right.get(x0, y), out.right.get((x0 + 1).min(w - 1), y));
                let l = out.left.get(x, y);
                for c in 0..3 {
                    err += f64::from((a[c] * (1.0 - t) + b[c] * t - l[c]).abs());
                }
                n += 3;
            }
        }
        let mean = err / n as f64;
        // Occluded pixels are included (no mask after resizing), hence a loose bound.
        assert!(n > 10_000 && mean < 4.0, "seed {seed}: {n} samples, mean error {mean}");
    }
}

#[test]
fn symmetric_colour_jitter_treats_both_views_alike() {
    let img = RgbImage::from_fn(120, 100, |x, y| [(x * 2) as f32, (y * 2) as f32, 100.0]);
    let d = DisparityMap::filled(120, 100, 3.0);
    let cfg =
        AugmentConfig { brightness: 0.4, contrast: 0.4, saturation: [0.6, 1.4], hue: 0.1, ..identity_cfg([90, 100]) };
    let out = augment(&cfg, &img, &img, &d, None, 9).unwrap();
    assert!(out.left == out.right, "same draw applied to identical views");
    assert!(out.left != img.crop(0, 0, 100, 90).unwrap());
    let asym = AugmentConfig { asymmetric_color_prob: 1.0, ..cfg };
    let out = augment(&asym, &img, &img, &d, None, 9).unwrap();
    assert!(out.left != out.right, "independent draws");
}

#[test]
fn mismatched_sizes_are_an_error() {
    let a = RgbImage::new(50, 40);
    let b = RgbImage::new(51, 40);
    let d = DisparityMap::filled(50, 40, 1.0);
    assert!(augment(&AugmentConfig::with_crop(16, 16), &a, &b, &d, None, 0).is_err());
    let cfg = AugmentConfig { spatial_prob: 0.0, ..AugmentConfig::with_crop(64, 64) };
    let e = augment(&cfg, &a, &a, &d, None, 0).unwrap_err();
    assert!(e.to_string().contains("too small"), "{e}");
}
