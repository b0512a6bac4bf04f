//! RAFT-Stereo's dense `FlowAugmentor` (SceneFlow training), deterministic per seed; the sparse
//! one for real data sets with holes in their ground truth is in [`sparse`].
//!
//! Order, as in `core/utils/augmentor.py`: colour → eraser → spatial → crop.
//! - **Colour** ([`color`]): `ColorJitter(brightness, contrast, saturation_range, hue)` then
//!   `AdjustGamma`; with probability `asymmetric_color_prob` (0.2) each view gets its own draw,
//!   otherwise both views share one draw applied to them as one stacked image.
//! - **Eraser**: with probability `eraser_prob` (0.5), 1–2 boxes with sides in 50..=99 px at a
//!   random top-left corner (clipped by the border) are filled with the right image's mean colour,
//!   on the right image only.
//! - **Spatial**: `s = 2^U(min_scale, max_scale)`; with probability `stretch_prob` (0.8) the axes
//!   get independent stretches `2^U(-max_stretch, max_stretch)`; each factor is clipped to at least
//!   `max((ch + 8) / h, (cw + 8) / w)`; with probability `spatial_prob` (1.0) images are resized
//!   with `INTER_LINEAR` ([`crate::resize`]) and the disparity is resized **both** bilinearly and
//!   by nearest neighbour, each multiplied by `sx`. There is no flip (RAFT disables it).
//! - **Crop**: with `yjitter`, the crop's top-left corner is drawn 2 px inside the border
//!   (`y0 ∈ [2, H - ch - 2)`, `x0 ∈ [2, W - cw - 2)`) and the right image's crop row is
//!   `y0 + randint(-2, 2)`; otherwise `y0 ∈ [0, H - ch]`, `x0 ∈ [0, W - cw]`.

pub mod color;
pub mod sparse;

pub use sparse::{augment_sparse, resize_sparse_disparity};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use dgstereo_core::{Error, Result};

use crate::image::{DisparityMap, Mask, RgbImage};
use crate::resize::{resize_disparity, resize_mask, resize_rgb};
use color::{JitterParams, adjust_gamma, apply_jitter};

/// Parameters of the dense augmentor. [`Default`] is RAFT-Stereo's README SceneFlow recipe
/// (`--spatial_scale -0.2 0.4 --saturation_range 0 1.4`) at the default crop 320x720.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AugmentConfig {
    /// Crop `[height, width]`.
    pub crop: [usize; 2],
    /// Lower end of `log2` of the scale.
    pub min_scale: f64,
    /// Upper end of `log2` of the scale.
    pub max_scale: f64,
    /// Probability of independent per-axis stretch.
    pub stretch_prob: f64,
    /// Largest `|log2|` of the per-axis stretch.
    pub max_stretch: f64,
    /// Probability of resizing at all.
    pub spatial_prob: f64,
    /// Brightness jitter (factor in `1 ± brightness`).
    pub brightness: f32,
    /// Contrast jitter.
    pub contrast: f32,
    /// Saturation factor range.
    pub saturation: [f32; 2],
    /// Hue jitter, fraction of the circle (RAFT: `0.5 / 3.14`).
    pub hue: f32,
    /// `AdjustGamma` ranges `[gamma_min, gamma_max, gain_min, gain_max]` (`[1, 1, 1, 1]` = off).
    pub gamma: [f32; 4],
    /// Probability of jittering the two views independently.
    pub asymmetric_color_prob: f64,
    /// Probability of the eraser.
    pub eraser_prob: f64,
    /// Eraser box sides, `[min, max)` in pixels.
    pub eraser_size: [usize; 2],
    /// Vertical jitter of the right crop.
    pub yjitter: bool,
}

impl Default for AugmentConfig {
    fn default() -> Self {
        Self {
            crop: [320, 720],
            min_scale: -0.2,
            max_scale: 0.4,
            stretch_prob: 0.8,
            max_stretch: 0.2,
            spatial_prob: 1.0,
            brightness: 0.4,
            contrast: 0.4,
            saturation: [0.0, 1.4],
            // RAFT-Stereo writes 3.14, not π.
            #[allow(clippy::approx_constant)]
            hue: 0.5 / 3.14,
            gamma: [1.0, 1.0, 1.0, 1.0],
            asymmetric_color_prob: 0.2,
            eraser_prob: 0.5,
            eraser_size: [50, 100],
            yjitter: true,
        }
    }
}

impl AugmentConfig {
    /// The defaults with another crop `[height, width]`.
    pub fn with_crop(height: usize, width: usize) -> Self {
        Self { crop: [height, width], ..Self::default() }
    }
}

/// An augmented training sample, all maps `crop` sized.
#[derive(Clone, Debug, PartialEq)]
pub struct AugmentedSample {
    /// Left view.
    pub left: RgbImage,
    /// Right view (erased, y-jittered).
    pub right: RgbImage,
    /// Disparity resized bilinearly (`INTER_LINEAR`) and multiplied by `sx`.
    pub disparity: DisparityMap,
    /// Disparity resized by nearest neighbour and multiplied by `sx`.
    pub disparity_nearest: DisparityMap,
    /// Input validity resized by nearest neighbour, AND finite bilinear disparity.
    pub valid: Mask,
    /// The scale factors `[sx, sy]` applied (1 when no resize happened).
    pub scale: [f64; 2],
}

/// Applies the dense augmentation to one sample; `valid` defaults to finite disparity.
///
/// Errors when the views and maps differ in size, or when the (resized) image is smaller than the
/// crop plus the y-jitter margin (possible only with `spatial_prob < 1`).
pub fn augment(
    cfg: &AugmentConfig,
    left: &RgbImage,
    right: &RgbImage,
    disparity: &DisparityMap,
    valid: Option<&Mask>,
    seed: u64,
) -> Result<AugmentedSample> {
    let (w, h) = (left.width, left.height);
    let valid = checked_validity(left, right, disparity, valid, DisparityMap::valid_finite)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut l, mut r) = (left.clone(), right.clone());

    // Colour.
    if rng.gen_bool(cfg.asymmetric_color_prob.clamp(0.0, 1.0)) {
        for img in [&mut l, &mut r] {
            let p = JitterParams::draw(&mut rng, cfg.brightness, cfg.contrast, cfg.saturation, cfg.hue);
            apply_jitter(&mut [img], &p);
            gamma(&mut rng, cfg, img);
        }
    } else {
        jitter_jointly(&mut rng, cfg, &mut l, &mut r);
    }

    // Eraser.
    if rng.gen_bool(cfg.eraser_prob.clamp(0.0, 1.0)) {
        erase(&mut rng, cfg, &mut r);
    }

    // Spatial.
    let [ch, cw] = cfg.crop;
    let min_scale = ((ch + 8) as f64 / h as f64).max((cw + 8) as f64 / w as f64);
    let s = 2f64.powf(uniform(&mut rng, cfg.min_scale, cfg.max_scale));
    let (mut sx, mut sy) = (s, s);
    if rng.gen_bool(cfg.stretch_prob.clamp(0.0, 1.0)) {
        sx *= 2f64.powf(uniform(&mut rng, -cfg.max_stretch, cfg.max_stretch));
        sy *= 2f64.powf(uniform(&mut rng, -cfg.max_stretch, cfg.max_stretch));
    }
    sx = sx.max(min_scale);
    sy = sy.max(min_scale);
    let (d_lin, d_near, valid, scale) = if rng.gen_bool(cfg.spatial_prob.clamp(0.0, 1.0)) {
        l = resize_rgb(&l, sx, sy);
        r = resize_rgb(&r, sx, sy);
        let (lin, near) = resize_disparity(disparity, sx, sy);
        (lin, near, resize_mask(&valid, sx, sy), [sx, sy])
    } else {
        (disparity.clone(), disparity.clone(), valid, [1.0, 1.0])
    };

    // Crop.
    let (w2, h2) = (l.width, l.height);
    let margin = if cfg.yjitter { 4 } else { 0 };
    if w2 < cw + margin + usize::from(cfg.yjitter) || h2 < ch + margin + usize::from(cfg.yjitter) {
        return Err(Error::Shape(format!("augment: image {w2}x{h2} is too small for crop {cw}x{ch}")));
    }
    let (x0, y0, y1) = if cfg.yjitter {
        let y0 = rng.gen_range(2..h2 - ch - 2);
        let x0 = rng.gen_range(2..w2 - cw - 2);
        let y1 = (y0 as i64 + rng.gen_range(-2i64..=2)) as usize;
        (x0, y0, y1)
    } else {
        (rng.gen_range(0..=w2 - cw), rng.gen_range(0..=h2 - ch), 0)
    };
    let y1 = if cfg.yjitter { y1 } else { y0 };
    let disparity = d_lin.crop(x0, y0, cw, ch)?;
    let valid = valid.crop(x0, y0, cw, ch)?;
    let valid = Mask {
        width: cw,
        height: ch,
        data: valid.data.iter().zip(&disparity.data).map(|(v, d)| *v && d.is_finite()).collect(),
    };
    Ok(AugmentedSample {
        left: l.crop(x0, y0, cw, ch)?,
        right: r.crop(x0, y1, cw, ch)?,
        disparity,
        disparity_nearest: d_near.crop(x0, y0, cw, ch)?,
        valid,
        scale,
    })
}

/// Checks that both views and the disparity (and `valid`, if given) have one size; returns
/// `valid`, or `default` of the disparity when there is none.
fn checked_validity(
    left: &RgbImage,
    right: &RgbImage,
    disparity: &DisparityMap,
    valid: Option<&Mask>,
    default: fn(&DisparityMap) -> Mask,
) -> Result<Mask> {
    let (w, h) = (left.width, left.height);
    if (right.width, right.height) != (w, h) || (disparity.width, disparity.height) != (w, h) {
        return Err(Error::Shape(format!(
            "augment: left {w}x{h}, right {}x{}, disparity {}x{}",
            right.width, right.height, disparity.width, disparity.height
        )));
    }
    match valid {
        Some(m) if (m.width, m.height) != (w, h) => {
            Err(Error::Shape(format!("augment: valid mask {}x{} for images {w}x{h}", m.width, m.height)))
        }
        Some(m) => Ok(m.clone()),
        None => Ok(default(disparity)),
    }
}

/// One colour-jitter and gamma draw applied to both views (as one stacked image in RAFT).
fn jitter_jointly(rng: &mut ChaCha8Rng, cfg: &AugmentConfig, l: &mut RgbImage, r: &mut RgbImage) {
    let p = JitterParams::draw(rng, cfg.brightness, cfg.contrast, cfg.saturation, cfg.hue);
    apply_jitter(&mut [&mut *l, &mut *r], &p);
    let (g, gain) = draw_gamma(rng, cfg);
    adjust_gamma(l, g, gain);
    adjust_gamma(r, g, gain);
}

fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    if hi > lo { rng.gen_range(lo..hi) } else { lo }
}

fn draw_gamma(rng: &mut ChaCha8Rng, cfg: &AugmentConfig) -> (f32, f32) {
    let [g0, g1, k0, k1] = cfg.gamma;
    let gain = if k1 > k0 { rng.gen_range(k0..k1) } else { k0 };
    let gamma = if g1 > g0 { rng.gen_range(g0..g1) } else { g0 };
    (gamma, gain)
}

fn gamma(rng: &mut ChaCha8Rng, cfg: &AugmentConfig, img: &mut RgbImage) {
    let (g, gain) = draw_gamma(rng, cfg);
    adjust_gamma(img, g, gain);
}

/// Fills 1–2 random boxes of `img` with its mean colour (RAFT's `eraser_transform`).
fn erase(rng: &mut ChaCha8Rng, cfg: &AugmentConfig, img: &mut RgbImage) {
    let (w, h) = (img.width, img.height);
    let n = img.plane_len() as f64;
    let mean: Vec<f32> = (0..3).map(|c| (img.plane(c).iter().map(|v| f64::from(*v)).sum::<f64>() / n) as f32).collect();
    let [lo, hi] = cfg.eraser_size;
    for _ in 0..rng.gen_range(1..3) {
        let x0 = rng.gen_range(0..w);
        let y0 = rng.gen_range(0..h);
        let dx = if hi > lo { rng.gen_range(lo..hi) } else { lo };
        let dy = if hi > lo { rng.gen_range(lo..hi) } else { lo };
        for y in y0..(y0 + dy).min(h) {
            for x in x0..(x0 + dx).min(w) {
                img.set(x, y, [mean[0], mean[1], mean[2]]);
            }
        }
    }
}
