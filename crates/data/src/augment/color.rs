//! Photometric augmentation: torchvision's `ColorJitter` and `AdjustGamma` on 0..255 images.
//! (`adjust_gamma` with gamma and gain 1 is skipped, so an all-neutral jitter is exactly the identity.)
//!
//! `ColorJitter(brightness, contrast, saturation, hue)` draws the four factors and a random order
//! of the four operations, then applies them; every operation clamps to 0..255:
//! - brightness `f`: `img · f`;
//! - contrast `f`: blend with the mean grey level `m` of the (whole) image: `f · img + (1-f) · m`;
//! - saturation `f`: blend with the per-pixel grey `0.299 R + 0.587 G + 0.114 B`;
//! - hue `h` (a fraction of the colour circle): rotate the hue in HSV space.
//!
//! RAFT-Stereo jitters on `uint8` PIL images and so rounds after each step; here samples stay
//! `f32` (no rounding).

use rand::Rng;

use crate::image::RgbImage;

/// Factors of one `ColorJitter` draw.
#[derive(Clone, Debug, PartialEq)]
pub struct JitterParams {
    /// Order of the operations: 0 brightness, 1 contrast, 2 saturation, 3 hue.
    pub order: [usize; 4],
    /// Brightness factor.
    pub brightness: f32,
    /// Contrast factor.
    pub contrast: f32,
    /// Saturation factor.
    pub saturation: f32,
    /// Hue shift, fraction of the circle.
    pub hue: f32,
}

impl JitterParams {
    /// Draws factors: brightness and contrast in `1 ± b`, `1 ± c`, saturation in `[s0, s1]`,
    /// hue in `±h`, and a random order.
    pub fn draw(rng: &mut impl Rng, brightness: f32, contrast: f32, saturation: [f32; 2], hue: f32) -> Self {
        let mut order = [0, 1, 2, 3];
        for i in (1..4).rev() {
            order.swap(i, rng.gen_range(0..=i));
        }
        let u = |rng: &mut dyn rand::RngCore, lo: f32, hi: f32| {
            if hi > lo { rng.gen_range(lo..=hi) } else { lo }
        };
        Self {
            order,
            brightness: u(rng, (1.0 - brightness).max(0.0), 1.0 + brightness),
            contrast: u(rng, (1.0 - contrast).max(0.0), 1.0 + contrast),
            saturation: u(rng, saturation[0], saturation[1]),
            hue: u(rng, -hue, hue),
        }
    }
}

fn grey(r: f32, g: f32, b: f32) -> f32 {
    0.299 * r + 0.587 * g + 0.114 * b
}

/// Applies jitter factors to a group of images treated as one (RAFT stacks the two views, so the
/// contrast mean is over both).
pub fn apply_jitter(images: &mut [&mut RgbImage], p: &JitterParams) {
    for &op in &p.order {
        match op {
            0 => {
                for img in images.iter_mut() {
                    img.data.iter_mut().for_each(|v| *v = (*v * p.brightness).clamp(0.0, 255.0));
                }
            }
            1 => {
                let (mut sum, mut n) = (0f64, 0usize);
                for img in images.iter() {
                    let (r, g, b) = (img.plane(0), img.plane(1), img.plane(2));
                    for i in 0..img.plane_len() {
                        sum += f64::from(grey(r[i], g[i], b[i]));
                    }
                    n += img.plane_len();
                }
                let m = (sum / n.max(1) as f64) as f32;
                for img in images.iter_mut() {
                    img.data.iter_mut().for_each(|v| *v = (p.contrast * *v + (1.0 - p.contrast) * m).clamp(0.0, 255.0));
                }
            }
            2 => {
                for img in images.iter_mut() {
                    let n = img.plane_len();
                    for i in 0..n {
                        let (r, g, b) = (img.data[i], img.data[n + i], img.data[2 * n + i]);
                        let l = grey(r, g, b);
                        for c in 0..3 {
                            let v = img.data[c * n + i];
                            img.data[c * n + i] = (p.saturation * v + (1.0 - p.saturation) * l).clamp(0.0, 255.0);
                        }
                    }
                }
            }
            _ => {
                if p.hue != 0.0 {
                    for img in images.iter_mut() {
                        shift_hue(img, p.hue);
                    }
                }
            }
        }
    }
}

/// Rotates the hue of every pixel by `h` (fraction of the circle).
pub fn shift_hue(img: &mut RgbImage, h: f32) {
    let n = img.plane_len();
    for i in 0..n {
        let rgb = [img.data[i] / 255.0, img.data[n + i] / 255.0, img.data[2 * n + i] / 255.0];
        let [hh, s, v] = rgb_to_hsv(rgb);
        let out = hsv_to_rgb([(hh + h).rem_euclid(1.0), s, v]);
        for (c, v) in out.iter().enumerate() {
            img.data[c * n + i] = (v * 255.0).clamp(0.0, 255.0);
        }
    }
}

/// RGB in 0..1 to HSV in 0..1.
pub fn rgb_to_hsv([r, g, b]: [f32; 3]) -> [f32; 3] {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let s = if max > 0.0 { d / max } else { 0.0 };
    let h = if d == 0.0 {
        0.0
    } else if max == r {
        ((g - b) / d).rem_euclid(6.0) / 6.0
    } else if max == g {
        ((b - r) / d + 2.0) / 6.0
    } else {
        ((r - g) / d + 4.0) / 6.0
    };
    [h, s, max]
}

/// HSV in 0..1 to RGB in 0..1.
pub fn hsv_to_rgb([h, s, v]: [f32; 3]) -> [f32; 3] {
    let h6 = h.rem_euclid(1.0) * 6.0;
    let i = h6.floor();
    let f = h6 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match i as i32 % 6 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

/// torchvision `adjust_gamma`: `255 · gain · (img / 255)^gamma`, clamped.
pub fn adjust_gamma(img: &mut RgbImage, gamma: f32, gain: f32) {
    if gamma == 1.0 && gain == 1.0 {
        return;
    }
    img.data.iter_mut().for_each(|v| *v = (255.0 * gain * (*v / 255.0).powf(gamma)).clamp(0.0, 255.0));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hsv_round_trips() {
        for rgb in [[0.2, 0.5, 0.9], [1.0, 0.0, 0.0], [0.3, 0.3, 0.3], [0.9, 0.8, 0.1]] {
            let back = hsv_to_rgb(rgb_to_hsv(rgb));
            for c in 0..3 {
                assert!((back[c] - rgb[c]).abs() < 1e-5, "{rgb:?} -> {back:?}");
            }
        }
        // Pure red shifted by a third of the circle becomes green.
        let g = hsv_to_rgb([(rgb_to_hsv([1.0, 0.0, 0.0])[0] + 1.0 / 3.0) % 1.0, 1.0, 1.0]);
        assert!((g[1] - 1.0).abs() < 1e-5 && g[0].abs() < 1e-5);
    }

    #[test]
    fn each_operation_does_what_torchvision_does() {
        let base = RgbImage::from_fn(2, 1, |x, _| if x == 0 { [100.0, 50.0, 200.0] } else { [0.0, 0.0, 0.0] });
        let id = JitterParams { order: [0, 1, 2, 3], brightness: 1.0, contrast: 1.0, saturation: 1.0, hue: 0.0 };
        let mut img = base.clone();
        apply_jitter(&mut [&mut img], &id);
        assert!(img.data.iter().zip(&base.data).all(|(a, b)| (a - b).abs() < 1e-4));
        let mut img = base.clone();
        apply_jitter(&mut [&mut img], &JitterParams { brightness: 2.0, ..id.clone() });
        assert_eq!(img.get(0, 0), [200.0, 100.0, 255.0]);
        // Contrast 0 gives the mean grey everywhere: mean of grey(100, 50, 200) = 82.05 and 0.
        let mut img = base.clone();
        apply_jitter(&mut [&mut img], &JitterParams { contrast: 0.0, ..id.clone() });
        assert!(img.data.iter().all(|v| (v - 41.025).abs() < 1e-3));
        // Saturation 0 gives per-pixel grey.
        let mut img = base.clone();
        apply_jitter(&mut [&mut img], &JitterParams { saturation: 0.0, ..id.clone() });
        assert!(img.get(0, 0).iter().all(|v| (v - 82.05).abs() < 1e-3));
    }
}
