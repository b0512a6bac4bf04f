//! Random scene generation: how many surfaces, of which kinds, where, at which disparity.

use std::f64::consts::PI;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::SyntheticConfig;
use super::random_texture::{smooth_texture, styled_texture};
use super::scene::{SyntheticSample, SyntheticScene};
use super::surface::{DisparityField, Outline, Surface};

impl SyntheticScene {
    /// Generates a random scene with `config`, deterministic per `seed`.
    pub fn random(config: &SyntheticConfig, seed: u64) -> Self {
        random_scene(config, seed)
    }
}

/// Generates and renders a random scene: the training source and test fixture.
pub fn generate(config: &SyntheticConfig, seed: u64) -> SyntheticSample {
    SyntheticScene::random(config, seed).render()
}

fn angle(rng: &mut ChaCha8Rng) -> (f64, f64) {
    let t: f64 = rng.gen_range(0.0..PI);
    (t.cos(), t.sin())
}

/// A random scene; see [`SyntheticScene::random`].
fn random_scene(cfg: &SyntheticConfig, seed: u64) -> SyntheticScene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Texture kinds and their parameters come from another stream of the same seed.
    let mut style = ChaCha8Rng::seed_from_u64(seed);
    style.set_stream(1);
    let (w, h) = (cfg.width as f64, cfg.height as f64);
    let min_disparity = match cfg.min_disparity_range {
        Some([lo, hi]) if hi > lo => {
            let mut near = ChaCha8Rng::seed_from_u64(seed);
            near.set_stream(2);
            near.gen_range(lo..=hi)
        }
        Some([lo, _]) => lo,
        None => cfg.min_disparity,
    };
    let (dmin, dmax) = (min_disparity, cfg.max_disparity.max(min_disparity + 1.0));
    let range = dmax - dmin;
    let slant = cfg.max_slant.clamp(0.0, 0.9);

    // Background: d = c + a x + b y, at least dmin over the region both views can see
    // (x in [-dmax, w + dmax], y in [0, h]) and at most dmin + 0.25 range.
    let span_x = w + 2.0 * dmax;
    let budget = 0.2 * range;
    let a = rng.gen_range(-1.0..=1.0) * (budget * 0.3 / span_x).min(slant);
    let b = rng.gen_range(0.0..=1.0) * (budget * 0.7 / h.max(1.0)).min(slant);
    let corners = [(-dmax, 0.0), (w + dmax, 0.0), (-dmax, h), (w + dmax, h)];
    let low = corners.iter().map(|(x, y)| a * x + b * y).fold(f64::INFINITY, f64::min);
    let c = dmin - low + rng.gen_range(0.0..=0.05 * range);
    let smooth = smooth_texture(&mut rng, cfg);
    let texture = styled_texture(&mut style, cfg, smooth, &cfg.background_texture_weights, [0.0, w, 0.0, h]);
    let background =
        Surface::new(Outline::Everything, DisparityField { c, a, b, kx: 0.0, ky: 0.0, x0: 0.0, y0: 0.0 }, texture);
    let mut surfaces = vec![background];

    let n = if cfg.max_surfaces > cfg.min_surfaces {
        rng.gen_range(cfg.min_surfaces..=cfg.max_surfaces)
    } else {
        cfg.min_surfaces
    };
    let total: f64 = cfg.kind_weights.iter().map(|v| v.max(0.0)).sum::<f64>().max(1e-9);
    let side = w.min(h).max(4.0);
    for _ in 0..n {
        let mut pick = rng.gen_range(0.0..total);
        let mut kind = 3;
        for (i, wgt) in cfg.kind_weights.iter().enumerate() {
            if pick < wgt.max(0.0) {
                kind = i;
                break;
            }
            pick -= wgt.max(0.0);
        }
        // Surfaces may stick out of the left view by up to the largest disparity on the right,
        // so the right view's border columns are populated as well.
        let cx = rng.gen_range(-0.1 * w..1.1 * w + 0.5 * dmax);
        let cy = rng.gen_range(-0.1 * h..1.1 * h);
        let outline = if kind == 3 {
            let (cos, sin) = angle(&mut rng);
            let hw = rng.gen_range(0.8..3.5);
            let hh = rng.gen_range(0.2..0.7) * side;
            Outline::Rect { cx, cy, hw, hh, cos, sin }
        } else {
            let r = rng.gen_range(0.06..0.3) * side;
            match rng.gen_range(0..3) {
                0 => {
                    let (cos, sin) = angle(&mut rng);
                    Outline::Rect { cx, cy, hw: r * rng.gen_range(0.4..1.0), hh: r * rng.gen_range(0.4..1.0), cos, sin }
                }
                1 => {
                    let (cos, sin) = angle(&mut rng);
                    Outline::Ellipse {
                        cx,
                        cy,
                        rx: r * rng.gen_range(0.5..1.0),
                        ry: r * rng.gen_range(0.5..1.0),
                        cos,
                        sin,
                    }
                }
                _ => {
                    let mut harmonics = [(0.0, 0.0); 3];
                    for hm in harmonics.iter_mut() {
                        *hm = (rng.gen_range(0.0..0.18), rng.gen_range(0.0..2.0 * PI));
                    }
                    Outline::Blob { cx, cy, r0: r, harmonics }
                }
            }
        };
        let bb = outline.bounds();
        let radius = ((bb[1] - bb[0]).max(bb[3] - bb[2]) / 2.0).max(1.0);
        // Disparity at the centre, then slopes and curvature that keep the surface in range.
        let c = rng.gen_range(dmin + 0.1 * range..=dmax);
        let room = (c - dmin).min(dmax - c).max(0.0) * 0.9;
        let (mut a, mut b, mut kx, mut ky) = (0.0, 0.0, 0.0, 0.0);
        if kind == 1 || kind == 2 || (kind == 3 && rng.gen_bool(0.5)) {
            let smax = (room / (2.0 * radius)).min(slant);
            a = rng.gen_range(-1.0..=1.0) * smax;
            b = rng.gen_range(-1.0..=1.0) * smax;
        }
        if kind == 2 {
            let used = (a.abs() + b.abs()) * radius;
            let left_room = (room - used).max(0.0);
            // Each right ray meets the patch once: |2 kx u| <= (1 - a) / 2 over the patch.
            let kmax_x = ((1.0 - a) / (4.0 * radius)).min(left_room / (2.0 * radius * radius));
            let kmax_y = left_room / (2.0 * radius * radius);
            kx = rng.gen_range(-1.0..=1.0) * kmax_x;
            ky = rng.gen_range(-1.0..=1.0) * kmax_y;
        }
        let field = DisparityField { c, a, b, kx, ky, x0: (bb[0] + bb[1]) / 2.0, y0: (bb[2] + bb[3]) / 2.0 };
        let smooth = smooth_texture(&mut rng, cfg);
        let texture = styled_texture(&mut style, cfg, smooth, &cfg.texture_weights, bb);
        surfaces.push(Surface::new(outline, field, texture));
    }
    if cfg.lattice_prob > 0.0 {
        surfaces.extend(lattice(cfg, seed, [dmin, dmax], slant));
    }
    SyntheticScene { width: cfg.width, height: cfg.height, surfaces }
}

/// With probability `cfg.lattice_prob`, a lattice in the nearer part of `[dmin, dmax]` over a
/// large part of the view: bars 6-40 px apart and 15-45 % of that wide (at least 1.5 px), at any
/// angle, nearly fronto-parallel. Geometry from random stream 3 of the seed, texture style from 4.
fn lattice(cfg: &SyntheticConfig, seed: u64, [dmin, dmax]: [f64; 2], slant: f64) -> Option<Surface> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(3);
    if !rng.gen_bool(cfg.lattice_prob.min(1.0)) {
        return None;
    }
    let mut style = ChaCha8Rng::seed_from_u64(seed);
    style.set_stream(4);
    let (w, h) = (cfg.width as f64, cfg.height as f64);
    let side = w.min(h).max(4.0);
    let (cos, sin) = angle(&mut rng);
    let period = rng.gen_range(6.0..40.0f64).min(side / 2.0);
    let bar = (period * rng.gen_range(0.15..0.45)).max(1.5);
    let outline = Outline::Lattice {
        cx: rng.gen_range(0.2 * w..0.8 * w + 0.5 * dmax),
        cy: rng.gen_range(0.2 * h..0.8 * h),
        hw: rng.gen_range(0.2..0.6) * w,
        hh: rng.gen_range(0.2..0.6) * h,
        cos,
        sin,
        period,
        bar,
    };
    let bb = outline.bounds();
    let range = dmax - dmin;
    let c = rng.gen_range(dmin + 0.5 * range..=dmax - 0.05 * range);
    // A gentle slant that stays within the range over the lattice's box.
    let radius = ((bb[1] - bb[0]).max(bb[3] - bb[2]) / 2.0).max(1.0);
    let smax = ((c - dmin).min(dmax - c) * 0.9 / (2.0 * radius)).min(slant).min(0.05);
    let (a, b) = (rng.gen_range(-1.0..=1.0) * smax, rng.gen_range(-1.0..=1.0) * smax);
    let field = DisparityField { c, a, b, kx: 0.0, ky: 0.0, x0: (bb[0] + bb[1]) / 2.0, y0: (bb[2] + bb[3]) / 2.0 };
    let smooth = smooth_texture(&mut rng, cfg);
    let texture = styled_texture(&mut style, cfg, smooth, &cfg.texture_weights, bb);
    Some(Surface::new(outline, field, texture))
}
