//! A scene's surfaces and its rendering: ray casting from both views, with the ground truth.

use rayon::prelude::*;

use super::surface::Surface;
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
