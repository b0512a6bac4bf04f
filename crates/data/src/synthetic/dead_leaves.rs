//! The dead-leaves texture: layers of randomly placed, sized and coloured discs and rotated
//! rectangles with anti-aliased edges, the sharp-edged counterpart of the smooth gratings.
//!
//! Each level is a square lattice of `cell`-pixel cells; a cell holds at most one shape whose
//! centre lies in the cell and whose bounding radius is below `cell / 2 - edge_width`, so a point
//! can only be touched by the shapes of the 2x2 cells nearest to it. Everything a shape is (its
//! presence, depth, centre, size, form and colour) is read from a hash of its cell, so the
//! texture is a pure function of the point: no shape list is stored and evaluation costs a few
//! hashes per level. As in the dead-leaves model, depth is independent of size: the shapes
//! touching a point, of all levels, are composited in the order of their hashed depths.
//!
//! Edges are a smoothstep of the signed distance over `edge_width` pixels, so the pattern is
//! continuous and point sampling at the pixel centres behaves like a slightly blurred camera.

use super::hash::{hash_cell, mix64};

/// One scale of a [`DeadLeaves`] texture.
#[derive(Clone, Debug, PartialEq)]
pub struct LeafLevel {
    /// Cell size in pixels.
    pub cell: f64,
    /// Probability that a cell holds a shape, 0..1.
    pub density: f64,
    /// Smallest and largest bounding radius of a shape, in pixels (the largest is capped at
    /// `cell / 2 - edge_width` when evaluated).
    pub radius: [f64; 2],
}

/// Layered random shapes over a ground colour; see the module docs.
#[derive(Clone, Debug, PartialEq)]
pub struct DeadLeaves {
    /// Colour where no shape covers the point, 0..255.
    pub ground: [f64; 3],
    /// The scales, at most [`MAX_LEAF_LEVELS`].
    pub levels: Vec<LeafLevel>,
    /// How far shape colours depart from `ground` toward their random colour, 0..1.
    pub contrast: f64,
    /// Colourfulness of the random shape colours: 0 grey, 1 independent channels.
    pub saturation: f64,
    /// Probability that a shape is a rotated rectangle rather than a disc.
    pub rect_prob: f64,
    /// Width in pixels of the anti-aliased edge (> 0).
    pub edge_width: f64,
    /// Hash seed.
    pub seed: u64,
}

/// Reads 16 bits of `h` starting at bit `shift` as a number in `[0, 1)`.
#[inline]
fn unit16(h: u64, shift: u32) -> f64 {
    ((h >> shift) & 0xffff) as f64 / 65536.0
}

/// Most levels a texture may have (more are ignored).
pub const MAX_LEAF_LEVELS: usize = 8;

impl DeadLeaves {
    /// The colour at left-view point `(x, y)`, in 0..255.
    pub fn at(&self, x: f64, y: f64) -> [f32; 3] {
        let edge = self.edge_width.max(1e-3);
        // (depth, coverage, shape hash) of the shapes touching the point, front (deepest) first.
        let mut hits = [(0u64, 0.0f64, 0u64); 4 * MAX_LEAF_LEVELS];
        let mut n = 0;
        for (li, level) in self.levels.iter().take(MAX_LEAF_LEVELS).enumerate() {
            let cell = level.cell;
            let r_cap = 0.5 * cell - edge;
            if r_cap.is_nan() || r_cap <= 0.0 {
                continue;
            }
            let salt = mix64(self.seed ^ (li as u64 + 1).wrapping_mul(0xA24B_AED4_963E_E407));
            let (u, v) = (x / cell, y / cell);
            let (i0, j0) = ((u - 0.5).floor() as i64, (v - 0.5).floor() as i64);
            for (ci, cj) in [(i0, j0), (i0 + 1, j0), (i0, j0 + 1), (i0 + 1, j0 + 1)] {
                let h0 = hash_cell(ci, cj, salt);
                if unit16(h0, 0) >= level.density {
                    continue;
                }
                let cx = (ci as f64 + unit16(h0, 32)) * cell;
                let cy = (cj as f64 + unit16(h0, 48)) * cell;
                let (dx, dy) = (x - cx, y - cy);
                let dist2 = dx * dx + dy * dy;
                if dist2 >= (r_cap + edge).powi(2) {
                    continue;
                }
                let h1 = mix64(h0 ^ 0x5851_F42D_4C95_7F2D);
                let (r_lo, r_hi) = (level.radius[0].min(r_cap), level.radius[1].min(r_cap));
                let r = r_lo + (r_hi - r_lo).max(0.0) * unit16(h1, 0);
                let sd = if unit16(h1, 16) < self.rect_prob {
                    // Rectangle of half sizes (hw, hh) with half diagonal r, rotated by t.
                    let aspect = 0.25 + 0.75 * unit16(h1, 32);
                    let norm = (1.0 + aspect * aspect).sqrt();
                    let (hw, hh) = (r / norm, r * aspect / norm);
                    let (s, c) = (std::f64::consts::PI * unit16(h1, 48)).sin_cos();
                    ((dx * c + dy * s).abs() - hw).max((-dx * s + dy * c).abs() - hh)
                } else {
                    dist2.sqrt() - r
                };
                let t = (0.5 - sd / edge).clamp(0.0, 1.0);
                let alpha = t * t * (3.0 - 2.0 * t);
                if alpha <= 0.0 {
                    continue;
                }
                // Depth: 16 hashed bits above the level index, so ties cannot occur.
                let depth = (((h0 >> 16) & 0xffff) << 8) | li as u64;
                let mut k = n;
                while k > 0 && hits[k - 1].0 < depth {
                    hits[k] = hits[k - 1];
                    k -= 1;
                }
                hits[k] = (depth, alpha, h1);
                n += 1;
            }
        }
        let mut colour = [0.0f64; 3];
        let mut transmitted = 1.0f64;
        for &(_, alpha, h1) in &hits[..n] {
            let shape = self.shape_colour(mix64(h1 ^ 0x2545_F491_4F6C_DD1D));
            let w = transmitted * alpha;
            for (c, s) in colour.iter_mut().zip(shape) {
                *c += w * s;
            }
            transmitted *= 1.0 - alpha;
            if transmitted <= 0.0 {
                break;
            }
        }
        for (c, g) in colour.iter_mut().zip(self.ground) {
            *c += transmitted * g;
        }
        colour.map(|c| c.clamp(0.0, 255.0) as f32)
    }

    /// The colour of the shape whose colour hash is `h`.
    fn shape_colour(&self, h: u64) -> [f64; 3] {
        let grey = unit16(h, 48);
        let sat = self.saturation.clamp(0.0, 1.0);
        let mut c = [0.0; 3];
        for (i, ch) in c.iter_mut().enumerate() {
            let random = 255.0 * (grey * (1.0 - sat) + unit16(h, 16 * i as u32) * sat);
            *ch = self.ground[i] + self.contrast * (random - self.ground[i]);
        }
        c
    }
}
