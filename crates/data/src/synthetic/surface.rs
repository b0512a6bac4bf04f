//! Surfaces of a synthetic scene: an outline, a disparity field and a texture, all expressed in
//! left-view pixel coordinates (pixel `(i, j)` has its centre at `x = i, y = j`).

use super::texture::SurfaceTexture;

/// The outline of a surface in the left view.
#[derive(Clone, Debug, PartialEq)]
pub enum Outline {
    /// Covers the whole plane (the background).
    Everything,
    /// A rectangle of half sizes `hw x hh` rotated by the angle whose cosine and sine are given;
    /// thin structures are rectangles with `hw` of a few pixels.
    Rect {
        /// Centre x.
        cx: f64,
        /// Centre y.
        cy: f64,
        /// Half width (along the rotated x axis).
        hw: f64,
        /// Half height (along the rotated y axis).
        hh: f64,
        /// Cosine of the rotation.
        cos: f64,
        /// Sine of the rotation.
        sin: f64,
    },
    /// An ellipse of radii `rx, ry`, rotated.
    Ellipse {
        /// Centre x.
        cx: f64,
        /// Centre y.
        cy: f64,
        /// Radius along the rotated x axis.
        rx: f64,
        /// Radius along the rotated y axis.
        ry: f64,
        /// Cosine of the rotation.
        cos: f64,
        /// Sine of the rotation.
        sin: f64,
    },
    /// A trellis, fence or grille: the points of the rotated rectangle `hw x hh` that lie on a bar
    /// (`bar` pixels wide, one every `period` pixels along both rotated axes). Through its holes
    /// the surfaces behind it are seen, so both views have many small occlusions and a repetitive
    /// pattern whose wrong matches are a period away.
    Lattice {
        /// Centre x.
        cx: f64,
        /// Centre y.
        cy: f64,
        /// Half width (along the rotated x axis).
        hw: f64,
        /// Half height (along the rotated y axis).
        hh: f64,
        /// Cosine of the rotation.
        cos: f64,
        /// Sine of the rotation.
        sin: f64,
        /// Distance between neighbouring bars.
        period: f64,
        /// Width of a bar (< `period`).
        bar: f64,
    },
    /// A star-shaped blob: radius `r0 · (1 + Σ amp_k cos(k θ + phase_k))` for `k = 2, 3, 4`.
    Blob {
        /// Centre x.
        cx: f64,
        /// Centre y.
        cy: f64,
        /// Mean radius.
        r0: f64,
        /// `(amplitude, phase)` of harmonics 2, 3, 4; the amplitudes sum below 0.6.
        harmonics: [(f64, f64); 3],
    },
}

impl Outline {
    /// Whether the point `(x, y)` lies inside.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        match *self {
            Outline::Everything => true,
            Outline::Rect { cx, cy, hw, hh, cos, sin } => {
                let (u, v) = rotated(x - cx, y - cy, cos, sin);
                u.abs() <= hw && v.abs() <= hh
            }
            Outline::Lattice { cx, cy, hw, hh, cos, sin, period, bar } => {
                let (u, v) = rotated(x - cx, y - cy, cos, sin);
                u.abs() <= hw
                    && v.abs() <= hh
                    && ((u + hw).rem_euclid(period) < bar || (v + hh).rem_euclid(period) < bar)
            }
            Outline::Ellipse { cx, cy, rx, ry, cos, sin } => {
                let (u, v) = rotated(x - cx, y - cy, cos, sin);
                let (u, v) = (u / rx, v / ry);
                u * u + v * v <= 1.0
            }
            Outline::Blob { cx, cy, r0, harmonics } => {
                let (dx, dy) = (x - cx, y - cy);
                let r2 = dx * dx + dy * dy;
                if r2 > (r0 * 1.6).powi(2) {
                    return false;
                }
                let t = dy.atan2(dx);
                let mut r = 1.0;
                for (k, (a, p)) in harmonics.iter().enumerate() {
                    r += a * ((k as f64 + 2.0) * t + p).cos();
                }
                r2 <= (r0 * r).powi(2)
            }
        }
    }

    /// An axis-aligned box `[x0, x1] x [y0, y1]` holding the outline (infinite for the background).
    pub fn bounds(&self) -> [f64; 4] {
        match *self {
            Outline::Everything => [f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY],
            Outline::Rect { cx, cy, hw, hh, cos, sin } | Outline::Lattice { cx, cy, hw, hh, cos, sin, .. } => {
                let ex = hw * cos.abs() + hh * sin.abs();
                let ey = hw * sin.abs() + hh * cos.abs();
                [cx - ex, cx + ex, cy - ey, cy + ey]
            }
            Outline::Ellipse { cx, cy, rx, ry, .. } => {
                let r = rx.max(ry);
                [cx - r, cx + r, cy - r, cy + r]
            }
            Outline::Blob { cx, cy, r0, .. } => {
                let r = r0 * 1.6;
                [cx - r, cx + r, cy - r, cy + r]
            }
        }
    }
}

/// The offset `(dx, dy)` from a shape's centre in the shape's rotated axes (the rotation whose
/// cosine and sine are given).
fn rotated(dx: f64, dy: f64, cos: f64, sin: f64) -> (f64, f64) {
    (dx * cos + dy * sin, -dx * sin + dy * cos)
}

/// Disparity over a surface, in left-view coordinates:
/// `d(x, y) = c + a·u + b·v + kx·u² + ky·v²` with `u = x - x0`, `v = y - y0`.
///
/// With `kx = ky = 0` the surface is a plane in space (disparity is affine in image coordinates
/// for planes); `kx`, `ky` bend it into a cylinder-like patch. Generators keep
/// `1 - a - 2·kx·u > 0` over the surface, so each right-view ray meets it at most once.
#[derive(Clone, Debug, PartialEq)]
pub struct DisparityField {
    /// Disparity at `(x0, y0)`.
    pub c: f64,
    /// Slope along x.
    pub a: f64,
    /// Slope along y.
    pub b: f64,
    /// Curvature along x.
    pub kx: f64,
    /// Curvature along y.
    pub ky: f64,
    /// Reference x.
    pub x0: f64,
    /// Reference y.
    pub y0: f64,
}

impl DisparityField {
    /// A fronto-parallel field of constant disparity.
    pub fn constant(c: f64) -> Self {
        Self { c, a: 0.0, b: 0.0, kx: 0.0, ky: 0.0, x0: 0.0, y0: 0.0 }
    }

    /// The disparity at left-view point `(x, y)`.
    pub fn at(&self, x: f64, y: f64) -> f64 {
        let (u, v) = (x - self.x0, y - self.y0);
        self.c + self.a * u + self.b * v + self.kx * u * u + self.ky * v * v
    }

    /// The left-view x of the surface point seen at right-view `(xr, y)`, i.e. the solution of
    /// `xr = x - d(x, y)` on the branch where `x - d` increases with `x`; `None` if there is none.
    pub fn left_x_from_right(&self, xr: f64, y: f64) -> Option<f64> {
        let v = y - self.y0;
        let g = self.c + self.b * v + self.ky * v * v;
        // kx u² + (a - 1) u + (g + xr - x0) = 0, root with 2 kx u + (a - 1) < 0.
        let (qa, qb, qc) = (self.kx, self.a - 1.0, g + xr - self.x0);
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            return None;
        }
        let den = -qb + disc.sqrt();
        if den <= 0.0 {
            return None;
        }
        Some(self.x0 + 2.0 * qc / den)
    }
}

/// A surface of the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    /// Where it is in the left view.
    pub outline: Outline,
    /// Its disparity.
    pub field: DisparityField,
    /// Its colour, a function of the left-view point.
    pub texture: SurfaceTexture,
    /// Left-view box `[x0, x1, y0, y1]` of the outline.
    pub bounds: [f64; 4],
    /// Bounds `[min, max]` of the disparity over `bounds` (with a margin).
    pub disparity_bounds: [f64; 2],
}

impl Surface {
    /// A surface, computing its bounds (a plain [`super::Texture`] converts into a
    /// [`SurfaceTexture`] without shading).
    pub fn new(outline: Outline, field: DisparityField, texture: impl Into<SurfaceTexture>) -> Self {
        let texture = texture.into();
        let bounds = outline.bounds();
        let disparity_bounds = if bounds[0].is_finite() {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            let n = 8;
            for i in 0..=n {
                for j in 0..=n {
                    let x = bounds[0] + (bounds[1] - bounds[0]) * i as f64 / n as f64;
                    let y = bounds[2] + (bounds[3] - bounds[2]) * j as f64 / n as f64;
                    let d = field.at(x, y);
                    lo = lo.min(d);
                    hi = hi.max(d);
                }
            }
            let vertex = field.at(field.x0, field.y0);
            [lo.min(vertex) - 1.0, hi.max(vertex) + 1.0]
        } else {
            [f64::NEG_INFINITY, f64::INFINITY]
        };
        Self { outline, field, texture, bounds, disparity_bounds }
    }

    /// The disparity if the left-view point `(x, y)` is on this surface.
    #[inline]
    pub fn hit_left(&self, x: f64, y: f64) -> Option<f64> {
        let b = &self.bounds;
        if x < b[0] || x > b[1] || y < b[2] || y > b[3] || !self.outline.contains(x, y) {
            return None;
        }
        Some(self.field.at(x, y))
    }

    /// `(left x, disparity)` if the right-view point `(xr, y)` sees this surface.
    #[inline]
    pub fn hit_right(&self, xr: f64, y: f64) -> Option<(f64, f64)> {
        let b = &self.bounds;
        if y < b[2] || y > b[3] || xr < b[0] - self.disparity_bounds[1] || xr > b[1] - self.disparity_bounds[0] {
            return None;
        }
        let x = self.field.left_x_from_right(xr, y)?;
        self.hit_left(x, y).map(|d| (x, d))
    }
}
