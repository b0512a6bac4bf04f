//! The sparse augmentor: valid points are moved, never blended with holes; one colour draw for
//! both views; crops biased to the borders like the reference's margins.

use dgstereo_data::augment::resize_sparse_disparity;
use dgstereo_data::{AugmentConfig, DisparityMap, Mask, RgbImage, augment, augment_sparse};

/// A KITTI-like map: disparity `10 + x / 8` on every third pixel of every second row, 0 elsewhere.
fn sparse_map(w: usize, h: usize) -> (DisparityMap, Mask) {
    let mut data = vec![0.0f32; w * h];
    for y in (0..h).step_by(2) {
        for x in (0..w).step_by(3) {
            data[y * w + x] = 10.0 + x as f32 / 8.0;
        }
    }
    let valid = Mask { width: w, height: h, data: data.iter().map(|d| *d > 0.0).collect() };
    (DisparityMap { width: w, height: h, data }, valid)
}

/// An image whose red channel is the column index and green the row index.
fn coordinate_image(w: usize, h: usize) -> RgbImage {
    let mut img = RgbImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            img.set(x, y, [x as f32, y as f32, 100.0]);
        }
    }
    img
}

#[test]
fn resizing_moves_each_valid_point_to_its_scaled_pixel() {
    let (d, v) = sparse_map(30, 20);
    let (up, up_valid) = resize_sparse_disparity(&d, &v, 2.0, 2.0);
    assert_eq!((up.width, up.height), (60, 40));
    for y in 0..20 {
        for x in 0..30 {
            let (i, j) = (y * 30 + x, 2 * y * 60 + 2 * x);
            // Row 0 and column 0 of the result are dropped, as in the reference.
            let expected = v.data[i] && x > 0 && y > 0;
            assert_eq!(up_valid.data[j], expected, "({x}, {y})");
            if expected {
                assert_eq!(up.data[j], 2.0 * d.data[i]);
            }
        }
    }
    let moved = up_valid.data.iter().filter(|b| **b).count();
    let kept = (0..600).filter(|&i| v.data[i] && i % 30 > 0 && i / 30 > 0).count();
    assert_eq!(moved, kept, "every valid point lands on its own pixel when upscaling");
    assert!(up.data.iter().zip(&up_valid.data).all(|(d, ok)| *ok || *d == 0.0));
}

#[test]
fn downscaling_keeps_only_original_values() {
    let (d, v) = sparse_map(41, 23);
    let (small, valid) = resize_sparse_disparity(&d, &v, 0.37, 0.37);
    let inputs: Vec<f32> = d.data.iter().filter(|x| **x > 0.0).map(|x| x * 0.37f64 as f32).collect();
    let mut n = 0;
    for (x, ok) in small.data.iter().zip(&valid.data) {
        if *ok {
            n += 1;
            assert!(inputs.contains(x), "{x} is not a scaled input value");
        }
    }
    assert!(n > 0 && n <= inputs.len());
}

#[test]
fn sparse_augmentation_never_blends_ground_truth_with_holes() {
    let (w, h) = (200, 120);
    let (d, v) = sparse_map(w, h);
    let img = coordinate_image(w, h);
    let cfg = AugmentConfig::with_crop(64, 96);
    let mut resized = 0;
    for seed in 0..20 {
        let a = augment_sparse(&cfg, &img, &img, &d, Some(&v), seed).unwrap();
        assert_eq!((a.left.width, a.left.height, a.disparity.width, a.valid.height), (96, 64, 96, 64));
        assert_eq!(a.disparity, a.disparity_nearest);
        let s = a.scale[0] as f32;
        assert_eq!(a.scale[0], a.scale[1], "no stretch");
        if a.scale[0] != 1.0 {
            resized += 1;
        }
        let allowed: Vec<f32> = d.data.iter().filter(|x| **x > 0.0).map(|x| x * s).collect();
        for (x, ok) in a.disparity.data.iter().zip(&a.valid.data) {
            if *ok {
                assert!(allowed.contains(x), "seed {seed}: {x} blends ground truth");
            }
        }
        assert!(a.valid.data.iter().any(|b| *b), "seed {seed}: some ground truth survives");
        assert_eq!(a, augment_sparse(&cfg, &img, &img, &d, Some(&v), seed).unwrap(), "deterministic");
    }
    assert!(resized > 8 && resized < 20, "the spatial step runs with probability 0.8: {resized} of 20");
    // The dense augmentor on the same input interpolates into the holes.
    let dense = augment(&cfg, &img, &img, &d, Some(&v), 3).unwrap();
    let s = dense.scale[0] as f32;
    let allowed: Vec<f32> = d.data.iter().filter(|x| **x > 0.0).map(|x| x * s).collect();
    assert!(dense.disparity.data.iter().zip(&dense.valid.data).any(|(x, ok)| *ok && !allowed.contains(x)));
}

#[test]
fn both_views_get_one_colour_draw_and_the_same_rows() {
    let img = coordinate_image(160, 100);
    let (d, v) = sparse_map(160, 100);
    let cfg = AugmentConfig { eraser_prob: 0.0, asymmetric_color_prob: 1.0, ..AugmentConfig::with_crop(48, 64) };
    for seed in 0..10 {
        let a = augment_sparse(&cfg, &img, &img, &d, Some(&v), seed).unwrap();
        assert_eq!(a.left, a.right, "seed {seed}: identical views stay identical (no y-jitter, no asymmetry)");
    }
}

#[test]
fn crops_reach_both_borders_more_often_than_uniformly() {
    let (w, h) = (120, 60);
    let img = coordinate_image(w, h);
    let (d, v) = sparse_map(w, h);
    // No resizing and no colour change, so the crop's first pixel tells its corner.
    let cfg = AugmentConfig {
        min_scale: 0.0,
        max_scale: 0.0,
        brightness: 0.0,
        contrast: 0.0,
        saturation: [1.0, 1.0],
        hue: 0.0,
        eraser_prob: 0.0,
        ..AugmentConfig::with_crop(40, 80)
    };
    let (mut left_edge, mut right_edge) = (0, 0);
    for seed in 0..200 {
        let a = augment_sparse(&cfg, &img, &img, &d, Some(&v), seed).unwrap();
        let x0 = a.left.get(0, 0)[0].round() as usize;
        assert!(x0 <= w - 80);
        left_edge += usize::from(x0 == 0);
        right_edge += usize::from(x0 == w - 80);
    }
    // x0 = clip(randint(-50, 90), 0, 40): each border takes ~36 % of the draws (uniform: 2.4 %).
    assert!(left_edge > 40 && right_edge > 40, "{left_edge} at x0 = 0, {right_edge} at x0 = 40");
}

#[test]
fn mismatched_sizes_are_errors() {
    let img = coordinate_image(50, 40);
    let (d, v) = sparse_map(50, 41);
    let cfg = AugmentConfig::with_crop(16, 16);
    assert!(augment_sparse(&cfg, &img, &img, &d, Some(&v), 0).is_err());
}
