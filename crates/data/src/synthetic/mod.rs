//! Procedural synthetic stereo: random textured occluding surfaces in front of a background,
//! rendered for both views with exact disparity, deterministic per seed.
//!
//! A scene ([`SyntheticScene`]) is a background plane and a list of [`Surface`]s (fronto-parallel
//! planes, slanted planes, curved patches, thin bars), each with an outline, a disparity field and
//! a texture, all defined in left-view coordinates. Rendering is ray casting: a left pixel
//! `(x, y)` sees the surface of largest disparity whose outline contains it; a right pixel
//! `(xr, y)` sees, among the surfaces with a solution of `xr = x - d(x, y)` inside their outline,
//! the one of largest disparity, and takes that surface's texture at `(x, y)`. Both views thus show
//! the same texture at corresponding points, so warping the right view by the left disparity
//! reproduces the left view exactly wherever the point is visible in both views. Every texture
//! is therefore a deterministic function of the continuous left-view point.
//!
//! # Textures
//!
//! A [`SurfaceTexture`] is one of four kinds ([`TextureKind`]) times an optional [`Shading`]:
//!
//! - gratings: 2-4 sinusoidal gratings plus smooth value noise at full contrast ([`Texture`]);
//! - dead leaves: multi-scale layers of random discs and rotated rectangles with ~1 px
//!   anti-aliased edges, composited by random depth ([`DeadLeaves`]): the sharp edges of paint,
//!   print and clutter;
//! - flat: a uniform colour with value noise of at most 3 grey levels (walls, floors);
//! - low contrast: the gratings texture at 5-30 % of its amplitude.
//!
//! The shading is a brightness gain of 0.6-1.2, a linear ramp across the surface or a radial
//! falloff, a property of the surface point and so identical in both views.
//!
//! [`SyntheticConfig`] weighs the kinds separately for the foreground and the background and sets
//! the shading probability. Presets ([`TexturePreset`]): `smooth` (the default: gratings only, no
//! shading, the original generator, reproduced bit for bit) and `rich`
//! ([`SyntheticConfig::rich`]: foreground 35/35/15/15 % gratings/dead leaves/flat/low contrast,
//! background 25/35/20/20 %, half the surfaces shaded). The texture choices are drawn from a
//! second random stream of the seed, so a seed gives the same geometry under every mix.
//!
//! The far end of a scene is at `min_disparity` (default 1: a distant background), or, with
//! [`SyntheticConfig::min_disparity_range`], at a disparity drawn per scene: near scenes (rooms,
//! table tops, Middlebury's) where every point has a large disparity and the band of the left
//! view that the right view cannot see is wide.
//!
//! With [`SyntheticConfig::lattice_prob`], a share of the scenes gets a lattice in front
//! ([`Outline::Lattice`]: a trellis, fence or grille of thin bars, the scene seen through its
//! holes), from random streams of its own: thin repetitive structures with many small occlusions.
//!
//! Pixel centres are at integer coordinates. Disparity is positive, `x_right = x_left - d`.

mod dead_leaves;
mod generate;
mod random_texture;
mod surface;
mod texture;

pub use dead_leaves::{DeadLeaves, LeafLevel, MAX_LEAF_LEVELS};
pub use generate::{SyntheticConfig, TexturePreset};
pub use surface::{DisparityField, Outline, Surface};
pub use texture::{Grating, Pattern, Shading, SurfaceTexture, Texture, TextureKind};

use rayon::prelude::*;

use crate::image::{DisparityMap, Mask, RgbImage};

/// A scene: surfaces, background first; the image size it is rendered at.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticScene {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Surfaces; the first is the background, covering everything.
    pub surfaces: Vec<Surface>,
}

/// A rendered stereo pair with its ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticSample {
    /// Left view.
    pub left: RgbImage,
    /// Right view.
    pub right: RgbImage,
    /// Disparity of the left view (`x_right = x_left - d`), everywhere finite and positive.
    pub disparity: DisparityMap,
    /// Disparity of the right view (`x_left = x_right + d`).
    pub disparity_right: DisparityMap,
    /// Left view: `true` where the point is hidden in the right view or falls outside it.
    pub occlusion: Mask,
    /// Left view: `true` where the disparity is known (every pixel of a synthetic scene).
    pub valid: Mask,
    /// Left view: index into [`SyntheticScene::surfaces`] of the surface seen.
    pub surface_left: Vec<u16>,
    /// Right view: index of the surface seen (`u16::MAX` where none).
    pub surface_right: Vec<u16>,
}

/// What a ray of one view hits: surface index, left-view x of the point, disparity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index of the surface.
    pub surface: usize,
    /// Left-view x of the point (equals the pixel's x for a left-view ray).
    pub x_left: f64,
    /// Disparity of the point.
    pub disparity: f64,
}

impl SyntheticScene {
    /// Generates a random scene with `config`, deterministic per `seed`.
    pub fn random(config: &SyntheticConfig, seed: u64) -> Self {
        generate::random_scene(config, seed)
    }

    /// The nearest surface seen by the left view at `(x, y)`.
    pub fn hit_left(&self, x: f64, y: f64) -> Hit {
        let mut best = Hit { surface: 0, x_left: x, disparity: f64::NEG_INFINITY };
        for (i, s) in self.surfaces.iter().enumerate() {
            if let Some(d) = s.hit_left(x, y)
                && d > best.disparity
            {
                best = Hit { surface: i, x_left: x, disparity: d };
            }
        }
        best
    }

    /// The nearest surface seen by the right view at `(xr, y)`, if any.
    pub fn hit_right(&self, xr: f64, y: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, s) in self.surfaces.iter().enumerate() {
            if let Some((x, d)) = s.hit_right(xr, y)
                && best.is_none_or(|b| d > b.disparity)
            {
                best = Some(Hit { surface: i, x_left: x, disparity: d });
            }
        }
        best
    }

    /// The left view's colour at a continuous point.
    pub fn left_colour(&self, x: f64, y: f64) -> [f32; 3] {
        let h = self.hit_left(x, y);
        self.surfaces[h.surface].texture.at(x, y)
    }

    /// The right view's colour at a continuous point (black where no surface is seen).
    pub fn right_colour(&self, xr: f64, y: f64) -> [f32; 3] {
        match self.hit_right(xr, y) {
            Some(h) => self.surfaces[h.surface].texture.at(h.x_left, y),
            None => [0.0; 3],
        }
    }

    /// Whether the left-view point `(x, y)` is visible in the right view: inside its frame
    /// (`x - d >= -0.5`) and not hidden by a nearer surface.
    pub fn visible_in_right(&self, x: f64, y: f64) -> bool {
        let h = self.hit_left(x, y);
        let xr = x - h.disparity;
        if xr < -0.5 || xr > self.width as f64 - 0.5 {
            return false;
        }
        self.hit_right(xr, y).is_some_and(|r| r.surface == h.surface)
    }

    /// Renders both views and the ground truth.
    pub fn render(&self) -> SyntheticSample {
        let (w, h) = (self.width, self.height);
        let n = w * h;
        // Per row: left rgb, right rgb, disparity, right disparity, occlusion, surface ids.
        let rows: Vec<_> = (0..h)
            .into_par_iter()
            .map(|y| {
                let yf = y as f64;
                let mut lrgb = Vec::with_capacity(3 * w);
                let mut rrgb = Vec::with_capacity(3 * w);
                let mut disp = Vec::with_capacity(w);
                let mut disp_r = Vec::with_capacity(w);
                let mut occ = Vec::with_capacity(w);
                let mut surf = Vec::with_capacity(w);
                let mut surf_r = Vec::with_capacity(w);
                for x in 0..w {
                    let xf = x as f64;
                    let hl = self.hit_left(xf, yf);
                    lrgb.push(self.surfaces[hl.surface].texture.at(xf, yf));
                    disp.push(hl.disparity as f32);
                    surf.push(hl.surface as u16);
                    let xr = xf - hl.disparity;
                    let visible = xr >= -0.5 && self.hit_right(xr, yf).is_some_and(|r| r.surface == hl.surface);
                    occ.push(!visible);
                    match self.hit_right(xf, yf) {
                        Some(hr) => {
                            rrgb.push(self.surfaces[hr.surface].texture.at(hr.x_left, yf));
                            disp_r.push(hr.disparity as f32);
                            surf_r.push(hr.surface as u16);
                        }
                        None => {
                            rrgb.push([0.0; 3]);
                            disp_r.push(f32::NAN);
                            surf_r.push(u16::MAX);
                        }
                    }
                }
                (lrgb, rrgb, disp, disp_r, occ, surf, surf_r)
            })
            .collect();
        let mut left = RgbImage::new(w, h);
        let mut right = RgbImage::new(w, h);
        let mut disparity = Vec::with_capacity(n);
        let mut disparity_right = Vec::with_capacity(n);
        let mut occlusion = Vec::with_capacity(n);
        let mut surface_left = Vec::with_capacity(n);
        let mut surface_right = Vec::with_capacity(n);
        for (y, (lrgb, rrgb, d, dr, o, s, sr)) in rows.into_iter().enumerate() {
            for x in 0..w {
                left.set(x, y, lrgb[x]);
                right.set(x, y, rrgb[x]);
            }
            disparity.extend(d);
            disparity_right.extend(dr);
            occlusion.extend(o);
            surface_left.extend(s);
            surface_right.extend(sr);
        }
        SyntheticSample {
            left,
            right,
            disparity: DisparityMap { width: w, height: h, data: disparity },
            disparity_right: DisparityMap { width: w, height: h, data: disparity_right },
            occlusion: Mask { width: w, height: h, data: occlusion },
            valid: Mask::filled(w, h, true),
            surface_left,
            surface_right,
        }
    }
}

/// Generates and renders a random scene: the training source and test fixture.
pub fn generate(config: &SyntheticConfig, seed: u64) -> SyntheticSample {
    SyntheticScene::random(config, seed).render()
}
