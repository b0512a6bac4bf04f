//! Surface textures: what colour a surface has at a left-view point.
//!
//! A [`SurfaceTexture`] is a [`Pattern`] (the smooth [`Texture`] of gratings and value noise, or
//! the sharp-edged [`DeadLeaves`]) times an optional [`Shading`] gain. Every one is a
//! deterministic function of the continuous left-view point, which is what lets the renderer
//! show the same colour at corresponding points of the two views.

use super::dead_leaves::DeadLeaves;
use super::hash::hash_cell;
use super::photo::PhotoTexture;

/// Which random texture kind a surface got (see [`super::SyntheticConfig::texture_weights`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextureKind {
    /// Full-contrast gratings and value noise (the smooth generator's only kind).
    Gratings,
    /// Layered random discs and rectangles with anti-aliased edges.
    DeadLeaves,
    /// A nearly uniform colour (noise of at most a few grey levels).
    Flat,
    /// Gratings and noise at 5-30 % of the usual amplitude.
    LowContrast,
    /// A crop of a real photograph ([`super::SyntheticConfig::photo_prob`]; not among the
    /// weighted kinds of [`TextureKind::ALL`]).
    Photo,
}

impl TextureKind {
    /// The kinds in the order of the weight arrays of [`super::SyntheticConfig`].
    pub const ALL: [TextureKind; 4] = [Self::Gratings, Self::DeadLeaves, Self::Flat, Self::LowContrast];
}

/// The pattern of a surface, before shading.
#[derive(Clone, Debug, PartialEq)]
pub enum Pattern {
    /// Gratings and value noise (also the flat and low-contrast kinds).
    Smooth(Texture),
    /// Layered random shapes.
    DeadLeaves(DeadLeaves),
    /// A photograph.
    Photo(PhotoTexture),
}

/// A smooth multiplicative brightness gain over a surface, a property of the surface point (so
/// both views see it identically).
#[derive(Clone, Debug, PartialEq)]
pub enum Shading {
    /// A linear ramp from gain `from` at `origin` to gain `to` at `origin + length · dir`,
    /// constant beyond both ends.
    Ramp {
        /// Where the ramp starts.
        origin: [f64; 2],
        /// Unit direction of the ramp.
        dir: [f64; 2],
        /// Length of the ramp in pixels (> 0).
        length: f64,
        /// Gain at the start.
        from: f64,
        /// Gain at the end.
        to: f64,
    },
    /// A radial falloff `edge + (centre_gain - edge) / (1 + (r / radius)²)`.
    Radial {
        /// Centre of the falloff.
        centre: [f64; 2],
        /// Distance in pixels at which the gain is halfway between both values (> 0).
        radius: f64,
        /// Gain at the centre.
        centre_gain: f64,
        /// Gain far away.
        edge: f64,
    },
}

impl Shading {
    /// The gain at left-view point `(x, y)`.
    pub fn gain(&self, x: f64, y: f64) -> f64 {
        match *self {
            Shading::Ramp { origin, dir, length, from, to } => {
                let t = (((x - origin[0]) * dir[0] + (y - origin[1]) * dir[1]) / length).clamp(0.0, 1.0);
                from + (to - from) * t
            }
            Shading::Radial { centre, radius, centre_gain, edge } => {
                let (dx, dy) = ((x - centre[0]) / radius, (y - centre[1]) / radius);
                edge + (centre_gain - edge) / (1.0 + dx * dx + dy * dy)
            }
        }
    }
}

/// The texture of a surface: a pattern and an optional shading.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceTexture {
    /// The kind it was drawn as.
    pub kind: TextureKind,
    /// The pattern.
    pub pattern: Pattern,
    /// The brightness gain, if any.
    pub shading: Option<Shading>,
}

impl SurfaceTexture {
    /// The colour at left-view point `(x, y)`, in 0..255.
    #[inline]
    pub fn at(&self, x: f64, y: f64) -> [f32; 3] {
        let c = match &self.pattern {
            Pattern::Smooth(t) => t.at(x, y),
            Pattern::DeadLeaves(t) => t.at(x, y),
            Pattern::Photo(t) => t.at(x, y),
        };
        match &self.shading {
            None => c,
            Some(s) => {
                let g = s.gain(x, y) as f32;
                c.map(|v| (v * g).clamp(0.0, 255.0))
            }
        }
    }
}

impl From<Texture> for SurfaceTexture {
    /// A gratings texture without shading.
    fn from(t: Texture) -> Self {
        Self { kind: TextureKind::Gratings, pattern: Pattern::Smooth(t), shading: None }
    }
}

/// One sinusoidal grating of a texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Grating {
    /// Spatial frequency vector (radians per pixel) along x and y.
    pub k: [f64; 2],
    /// Phase.
    pub phase: f64,
    /// Amplitude per channel.
    pub amp: [f64; 3],
}

/// A smooth colour texture: a base colour, sinusoidal gratings and smooth value noise.
///
/// Every component is band-limited (wavelengths at least a few pixels), so the texture is well
/// approximated by linear interpolation between pixel centres. The flat and low-contrast kinds
/// ([`TextureKind`]) are textures of this type too, with tiny or scaled amplitudes.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Base colour, 0..255.
    pub base: [f64; 3],
    /// Gratings added to the base.
    pub gratings: Vec<Grating>,
    /// Noise lattice spacing in pixels (0 = no noise).
    pub noise_cell: f64,
    /// Noise amplitude per channel.
    pub noise_amp: [f64; 3],
    /// Noise hash seed.
    pub noise_seed: u64,
}

impl Texture {
    /// A nearly uniform colour: `base` plus value noise of amplitude `amp` grey levels on a
    /// lattice of `cell` pixels (no gratings).
    pub fn flat(base: [f64; 3], amp: f64, cell: f64, noise_seed: u64) -> Self {
        Self { base, gratings: Vec::new(), noise_cell: cell, noise_amp: [amp; 3], noise_seed }
    }

    /// The same texture with every grating and noise amplitude multiplied by `factor` (the
    /// low-contrast kind uses 0.05-0.3).
    pub fn scaled(mut self, factor: f64) -> Self {
        for g in &mut self.gratings {
            g.amp = g.amp.map(|a| a * factor);
        }
        self.noise_amp = self.noise_amp.map(|a| a * factor);
        self
    }

    /// The colour at left-view point `(x, y)`, clamped to 0..255.
    pub fn at(&self, x: f64, y: f64) -> [f32; 3] {
        let mut c = self.base;
        for g in &self.gratings {
            let s = (g.k[0] * x + g.k[1] * y + g.phase).sin();
            for (ch, a) in c.iter_mut().zip(g.amp) {
                *ch += a * s;
            }
        }
        if self.noise_cell > 0.0 {
            for (i, ch) in c.iter_mut().enumerate() {
                *ch += self.noise_amp[i]
                    * value_noise(x / self.noise_cell, y / self.noise_cell, self.noise_seed ^ (i as u64 * 0x9e37));
            }
        }
        [c[0].clamp(0.0, 255.0) as f32, c[1].clamp(0.0, 255.0) as f32, c[2].clamp(0.0, 255.0) as f32]
    }
}

/// A hash of `(ix, iy)` in `[-1, 1)`.
fn hash2(ix: i64, iy: i64, seed: u64) -> f64 {
    (hash_cell(ix, iy, seed) >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

/// Smooth value noise in `[-1, 1]` on a unit lattice, with smoothstep blending.
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (fx, fy) = (x.floor(), y.floor());
    let (tx, ty) = (x - fx, y - fy);
    let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let (ix, iy) = (fx as i64, fy as i64);
    let v00 = hash2(ix, iy, seed);
    let v10 = hash2(ix + 1, iy, seed);
    let v01 = hash2(ix, iy + 1, seed);
    let v11 = hash2(ix + 1, iy + 1, seed);
    let top = v00 + (v10 - v00) * sx;
    let bot = v01 + (v11 - v01) * sx;
    top + (bot - top) * sy
}
