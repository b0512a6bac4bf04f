//! Test helpers: a fresh scratch folder per test; the checks of a synthetic sample's two views.
#![allow(dead_code)]

use std::path::PathBuf;

use dgstereo_data::RgbImage;
use dgstereo_data::synthetic::{SyntheticSample, SyntheticScene};

/// A new empty folder under the system temp dir, unique to this process and `name`.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dgstereo-data-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Samples `img` at `(x, y)` with linear interpolation along x (clamped at the borders).
pub fn sample_x(img: &RgbImage, x: f64, y: usize) -> [f32; 3] {
    let x = x.clamp(0.0, (img.width - 1) as f64);
    let x0 = x.floor() as usize;
    let x1 = (x0 + 1).min(img.width - 1);
    let t = (x - x0 as f64) as f32;
    let (a, b) = (img.get(x0, y), img.get(x1, y));
    [0, 1, 2].map(|c| a[c] * (1.0 - t) + b[c] * t)
}

/// Asserts that the continuous right view of `scene` at `x - d` shows the left pixel's colour
/// (within 1e-3) at every pixel of `s` visible in both views; returns how many were checked.
pub fn assert_right_view_matches_left(scene: &SyntheticScene, s: &SyntheticSample, seed: u64) -> usize {
    let mut checked = 0;
    for y in 0..s.left.height {
        for x in 0..s.left.width {
            if s.occlusion.get(x, y) {
                continue;
            }
            let r = scene.right_colour(x as f64 - f64::from(s.disparity.get(x, y)), y as f64);
            let l = s.left.get(x, y);
            for c in 0..3 {
                assert!((r[c] - l[c]).abs() < 1e-3, "seed {seed} ({x},{y}) {l:?} vs {r:?}");
            }
            checked += 1;
        }
    }
    checked
}

/// Per-channel errors of the rendered right image, sampled linearly at `x - d`, against the left
/// image, at the visible pixels whose interpolation stays on their own surface.
pub fn warping_errors(s: &SyntheticSample) -> Vec<f32> {
    let w = s.left.width;
    let mut errors = Vec::new();
    for y in 0..s.left.height {
        for x in 0..w {
            if s.occlusion.get(x, y) {
                continue;
            }
            let xr = x as f64 - f64::from(s.disparity.get(x, y));
            // Skip points whose interpolation mixes two surfaces of the right view.
            let own = s.surface_left[y * w + x];
            let (x0, x1) = (xr.floor().max(0.0) as usize, (xr.ceil().max(0.0) as usize).min(w - 1));
            if s.surface_right[y * w + x0] != own || s.surface_right[y * w + x1] != own {
                continue;
            }
            let (r, l) = (sample_x(&s.right, xr, y), s.left.get(x, y));
            errors.extend((0..3).map(|c| (r[c] - l[c]).abs()));
        }
    }
    errors
}
