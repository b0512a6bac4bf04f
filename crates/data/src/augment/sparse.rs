//! RAFT-Stereo's `SparseFlowAugmentor`: the augmentation of real data sets whose ground truth
//! has holes (KITTI, ETH3D, Middlebury), deterministic per seed.
//!
//! Interpolating such a map would blend valid disparities with the holes' zeros at every hole
//! border, so the spatial step moves each valid point instead: its coordinates are scaled and
//! rounded to the nearest pixel of the resized grid, which gets the scaled disparity (the last
//! point wins where two land on one pixel), and every other pixel is invalid. Differences from
//! the dense augmentor ([`super::augment`]), as in `core/utils/augmentor.py`:
//! - **Colour**: one jitter and gamma draw for both views, always (no asymmetric draw).
//! - **Spatial**: with probability 0.8 (not 1), one scale for both axes (no stretch), clipped to
//!   at least `max((ch + 1) / h, (cw + 1) / w)`; points landing in row 0 or column 0 are dropped
//!   (the reference keeps `x > 0` and `y > 0`).
//! - **Crop**: `y0 = randint(0, H - ch + 20)`, `x0 = randint(-50, W - cw + 50)`, both clipped into
//!   the image (so crops at the borders are more likely); no y-jitter.
//!
//! The eraser is the dense one's. `disparity_nearest` equals `disparity` (there is nothing to
//! interpolate), so the edge-aware loss suppresses nothing on sparse data.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use dgstereo_core::{Error, Result};

use super::{AugmentConfig, AugmentedSample, checked_validity, erase, jitter_jointly, uniform};
use crate::image::{DisparityMap, Mask, RgbImage};
use crate::resize::{resize_rgb, scaled_size};

/// Probability of the spatial step (the dense augmentor's `spatial_prob` is not used).
pub const SPARSE_SPATIAL_PROB: f64 = 0.8;
/// The crop's extra room below and on both sides, in pixels (`margin_y`, `margin_x`).
pub const SPARSE_CROP_MARGIN: [i64; 2] = [20, 50];

/// Scatters the valid points of `disparity` onto the grid scaled by `(fx, fy)`; returns the map
/// (0 where no point landed) and its validity.
pub fn resize_sparse_disparity(disparity: &DisparityMap, valid: &Mask, fx: f64, fy: f64) -> (DisparityMap, Mask) {
    let (w, h) = (disparity.width, disparity.height);
    let (w1, h1) = scaled_size(w, h, fx, fy);
    let mut data = vec![0.0f32; w1 * h1];
    let mut mask = vec![false; w1 * h1];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let d = disparity.data[i];
            if !valid.data[i] || !d.is_finite() {
                continue;
            }
            let xx = (x as f64 * fx).round_ties_even();
            let yy = (y as f64 * fy).round_ties_even();
            if xx > 0.0 && yy > 0.0 && (xx as usize) < w1 && (yy as usize) < h1 {
                let j = yy as usize * w1 + xx as usize;
                data[j] = d * fx as f32;
                mask[j] = true;
            }
        }
    }
    (DisparityMap { width: w1, height: h1, data }, Mask { width: w1, height: h1, data: mask })
}

/// Applies the sparse augmentation to one sample; `valid` defaults to finite disparity `> 0`.
///
/// Errors when the views and maps differ in size, or when an image that is not resized is
/// smaller than the crop.
pub fn augment_sparse(
    cfg: &AugmentConfig,
    left: &RgbImage,
    right: &RgbImage,
    disparity: &DisparityMap,
    valid: Option<&Mask>,
    seed: u64,
) -> Result<AugmentedSample> {
    let (w, h) = (left.width, left.height);
    let valid = checked_validity(left, right, disparity, valid, DisparityMap::valid_positive)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut l, mut r) = (left.clone(), right.clone());

    // Colour: one draw for both views.
    jitter_jointly(&mut rng, cfg, &mut l, &mut r);

    // Eraser.
    if rng.gen_bool(cfg.eraser_prob.clamp(0.0, 1.0)) {
        erase(&mut rng, cfg, &mut r);
    }

    // Spatial: one scale, valid points moved rather than interpolated.
    let [ch, cw] = cfg.crop;
    let min_scale = ((ch + 1) as f64 / h as f64).max((cw + 1) as f64 / w as f64);
    let s = 2f64.powf(uniform(&mut rng, cfg.min_scale, cfg.max_scale)).max(min_scale);
    let (d, valid, scale) = if rng.gen_bool(SPARSE_SPATIAL_PROB) {
        l = resize_rgb(&l, s, s);
        r = resize_rgb(&r, s, s);
        let (d, v) = resize_sparse_disparity(disparity, &valid, s, s);
        (d, v, [s, s])
    } else {
        (disparity.clone(), valid, [1.0, 1.0])
    };

    // Crop, with the reference's margins, clipped into the image.
    let (w2, h2) = (l.width, l.height);
    if w2 < cw || h2 < ch {
        return Err(Error::Shape(format!("augment: image {w2}x{h2} is too small for crop {cw}x{ch}")));
    }
    let [my, mx] = SPARSE_CROP_MARGIN;
    let y0 = rng.gen_range(0..h2 as i64 - ch as i64 + my).clamp(0, (h2 - ch) as i64) as usize;
    let x0 = rng.gen_range(-mx..w2 as i64 - cw as i64 + mx).clamp(0, (w2 - cw) as i64) as usize;
    let disparity = d.crop(x0, y0, cw, ch)?;
    let valid = valid.crop(x0, y0, cw, ch)?;
    Ok(AugmentedSample {
        left: l.crop(x0, y0, cw, ch)?,
        right: r.crop(x0, y0, cw, ch)?,
        disparity_nearest: disparity.clone(),
        disparity,
        valid,
        scale,
    })
}
