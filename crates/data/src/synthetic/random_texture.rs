//! Random textures: the smooth gratings texture, drawn from the scene's main random stream
//! exactly as the smooth-only generator always did, and its restyling into the kind chosen by
//! [`SyntheticConfig::texture_weights`], drawn from a separate stream.
//!
//! Keeping the new choices off the main stream means a scene's geometry (outlines, disparities)
//! does not depend on the texture mix, and the default mix reproduces the smooth generator's
//! images bit for bit.

use std::f64::consts::PI;

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::config::SyntheticConfig;
use super::dead_leaves::{DeadLeaves, LeafLevel, MAX_LEAF_LEVELS};
use super::photo::{PhotoLibrary, PhotoTexture};
use super::texture::{Grating, Pattern, Shading, SurfaceTexture, Texture, TextureKind};

/// The smooth texture (2-4 gratings and value noise) from the main stream.
pub(super) fn smooth_texture(rng: &mut ChaCha8Rng, cfg: &SyntheticConfig) -> Texture {
    let base = [rng.gen_range(40.0..215.0), rng.gen_range(40.0..215.0), rng.gen_range(40.0..215.0)];
    let (lo, hi) = (cfg.min_wavelength.max(2.0).ln(), cfg.max_wavelength.max(cfg.min_wavelength.max(2.0)).ln());
    let n = rng.gen_range(2..=4);
    let gratings = (0..n)
        .map(|_| {
            let wl = if hi > lo { rng.gen_range(lo..=hi).exp() } else { lo.exp() };
            let t: f64 = rng.gen_range(0.0..PI);
            let f = 2.0 * PI / wl;
            let a: f64 = rng.gen_range(8.0..40.0);
            let tint = [rng.gen_range(0.5..1.0), rng.gen_range(0.5..1.0), rng.gen_range(0.5..1.0)];
            Grating { k: [f * t.cos(), f * t.sin()], phase: rng.gen_range(0.0..2.0 * PI), amp: tint.map(|c| a * c) }
        })
        .collect();
    let wl_min = cfg.min_wavelength.max(2.0);
    let noise_cell = rng.gen_range(wl_min..=cfg.max_wavelength.max(wl_min)) * 0.5 + wl_min * 0.5;
    let na: f64 = rng.gen_range(10.0..40.0);
    Texture {
        base,
        gratings,
        noise_cell,
        noise_amp: [na, na * rng.gen_range(0.5..1.0), na * rng.gen_range(0.5..1.0)],
        noise_seed: rng.r#gen(),
    }
}

/// Picks a kind with probabilities proportional to `weights` (negative and NaN weights count as
/// 0; gratings when every weight is 0).
fn pick_kind(style: &mut ChaCha8Rng, weights: &[f64; 4]) -> TextureKind {
    let w = weights.map(|v| v.max(0.0));
    let total: f64 = w.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return TextureKind::Gratings;
    }
    let mut pick = style.gen_range(0.0..total);
    for (kind, wgt) in TextureKind::ALL.into_iter().zip(w) {
        if pick < wgt {
            return kind;
        }
        pick -= wgt;
    }
    TextureKind::ALL.into_iter().zip(w).rev().find(|(_, v)| *v > 0.0).map_or(TextureKind::Gratings, |(k, _)| k)
}

/// Restyles `smooth` into a kind drawn with `weights` from the `style` stream, with a shading
/// over `extent` (`[x0, x1, y0, y1]`, finite) with probability `cfg.shading_prob`.
pub(super) fn styled_texture(
    style: &mut ChaCha8Rng,
    cfg: &SyntheticConfig,
    smooth: Texture,
    weights: &[f64; 4],
    extent: [f64; 4],
) -> SurfaceTexture {
    let kind = pick_kind(style, weights);
    let pattern = match kind {
        TextureKind::Gratings => Pattern::Smooth(smooth),
        TextureKind::LowContrast => Pattern::Smooth(smooth.scaled(style.gen_range(0.05..=0.3))),
        TextureKind::Flat => {
            let amp = style.gen_range(0.0..=3.0);
            Pattern::Smooth(Texture::flat(smooth.base, amp, smooth.noise_cell, smooth.noise_seed))
        }
        // `pick_kind` draws only the weighted kinds; a photo replaces one below.
        TextureKind::DeadLeaves | TextureKind::Photo => {
            Pattern::DeadLeaves(dead_leaves(style, cfg, smooth.base, extent))
        }
    };
    let (kind, pattern) = match photo(style, cfg) {
        Some(photo) => (TextureKind::Photo, Pattern::Photo(photo)),
        None => (kind, pattern),
    };
    let p = cfg.shading_prob;
    let shading = (p > 0.0 && style.gen_bool(p.min(1.0))).then(|| shading(style, extent));
    SurfaceTexture { kind, pattern, shading }
}

/// With probability `cfg.photo_prob` (drawn only where it is above 0), a photograph of
/// `cfg.photo_dir` at 0.5-2 photo pixels per view pixel (log-uniform), any rotation, a random
/// offset. A folder that does not load gives none (training checks it first, naming the key).
fn photo(style: &mut ChaCha8Rng, cfg: &SyntheticConfig) -> Option<PhotoTexture> {
    let p = cfg.photo_prob;
    if !(p > 0.0 && style.gen_bool(p.min(1.0))) {
        return None;
    }
    let library = PhotoLibrary::of_folder(cfg.photo_dir.as_deref()?).ok()?;
    let index = style.gen_range(0..library.photos.len());
    let (w, h) = (library.photos[index].width as f64, library.photos[index].height as f64);
    Some(PhotoTexture {
        scale: style.gen_range(0.5f64.ln()..=2.0f64.ln()).exp(),
        angle: style.gen_range(0.0..2.0 * PI),
        offset: [style.gen_range(0.0..w), style.gen_range(0.0..h)],
        library,
        index,
    })
}

/// A dead-leaves texture over `ground` for a surface of `extent`: levels from cells of 2-4
/// longest wavelengths (at most the surface's larger side) down to cells of twice the shortest
/// wavelength (at least 6 px), each covering roughly 20-45 % of the plane; random contrast,
/// colourfulness, share of rectangles and edge width.
fn dead_leaves(style: &mut ChaCha8Rng, cfg: &SyntheticConfig, ground: [f64; 3], extent: [f64; 4]) -> DeadLeaves {
    let wl_min = cfg.min_wavelength.max(2.0);
    let wl_max = cfg.max_wavelength.max(wl_min);
    let finest = (2.0 * wl_min).max(6.0);
    let side = (extent[1] - extent[0]).max(extent[3] - extent[2]);
    let ratio = style.gen_range(0.5..0.7);
    let mut cell = (2.0 * wl_max * style.gen_range(1.0f64..2.0)).min(side).max(finest);
    let mut levels = Vec::new();
    while levels.len() < MAX_LEAF_LEVELS && cell >= finest {
        levels.push(LeafLevel {
            cell,
            density: style.gen_range(0.6..1.0),
            radius: [style.gen_range(0.15..0.3) * cell, style.gen_range(0.4..0.5) * cell],
        });
        cell *= ratio;
    }
    // Some textures stop short of the finest scales.
    let keep = style.gen_range(levels.len().saturating_sub(2).max(1)..=levels.len().max(1));
    levels.truncate(keep);
    DeadLeaves {
        ground,
        levels,
        contrast: style.gen_range(0.25..=1.0),
        saturation: style.gen_range(0.0..=1.0),
        rect_prob: style.gen_range(0.0..0.7),
        edge_width: style.gen_range(0.7..1.2),
        seed: style.r#gen(),
    }
}

/// A shading over `extent`: a linear ramp between gains of 0.6-0.9 and 1.0-1.2 across the box
/// in a random direction (70 %), or a radial falloff from 1.0-1.2 to 0.6-0.9 (30 %).
fn shading(style: &mut ChaCha8Rng, extent: [f64; 4]) -> Shading {
    let [x0, x1, y0, y1] = extent;
    let (low, high) = (style.gen_range(0.6..0.9), style.gen_range(1.0..1.2));
    if style.gen_bool(0.7) {
        let (s, c) = style.gen_range(0.0..2.0 * PI).sin_cos();
        // Start at the box corner of smallest projection on the direction.
        let origin = [if c >= 0.0 { x0 } else { x1 }, if s >= 0.0 { y0 } else { y1 }];
        let length = ((x1 - x0) * c.abs() + (y1 - y0) * s.abs()).max(1.0);
        Shading::Ramp { origin, dir: [c, s], length, from: low, to: high }
    } else {
        let centre = [style.gen_range(x0..=x1), style.gen_range(y0..=y1)];
        let half_diagonal = 0.5 * (x1 - x0).hypot(y1 - y0);
        let radius = (style.gen_range(0.3..1.0) * half_diagonal).max(1.0);
        Shading::Radial { centre, radius, centre_gain: high, edge: low }
    }
}
