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
//! - low contrast: the gratings texture at 5-30 % of its amplitude;
//! - photo: a crop of a real photograph ([`PhotoTexture`], from a folder of
//!   [`SyntheticConfig::photo_dir`] with probability [`SyntheticConfig::photo_prob`], over any
//!   of the other kinds).
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

mod config;
mod dead_leaves;
mod generate;
mod hash;
mod photo;
mod random_texture;
mod scene;
mod surface;
mod texture;

pub use config::{SyntheticConfig, TexturePreset};
pub use dead_leaves::{DeadLeaves, LeafLevel, MAX_LEAF_LEVELS};
pub use generate::generate;
pub use photo::{PhotoLibrary, PhotoTexture};
pub use scene::{Hit, SyntheticSample, SyntheticScene};
pub use surface::{DisparityField, Outline, Surface};
pub use texture::{Grating, Pattern, Shading, SurfaceTexture, Texture, TextureKind};
