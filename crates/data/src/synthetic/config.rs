//! The synthetic generator's settings ([`SyntheticConfig`]) and its texture presets
//! ([`TexturePreset`]).

use serde::{Deserialize, Serialize};

/// Parameters of the synthetic scene generator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SyntheticConfig {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Fewest foreground surfaces.
    pub min_surfaces: usize,
    /// Most foreground surfaces.
    pub max_surfaces: usize,
    /// Smallest disparity (the far end of the background), > 0.
    pub min_disparity: f64,
    /// Largest disparity of any surface point.
    pub max_disparity: f64,
    /// Largest disparity slope `|∂d/∂x|`, `|∂d/∂y|` of slanted surfaces (< 1).
    pub max_slant: f64,
    /// Probabilities of the kinds fronto-parallel, slanted, curved, thin (normalised).
    pub kind_weights: [f64; 4],
    /// Shortest texture wavelength in pixels (smaller = sharper texture).
    pub min_wavelength: f64,
    /// Longest texture wavelength in pixels.
    pub max_wavelength: f64,
    /// Probabilities of the foreground texture kinds gratings, dead leaves, flat, low contrast
    /// (normalised; see [`super::TextureKind`]). Default: gratings only.
    #[serde(default = "gratings_only")]
    pub texture_weights: [f64; 4],
    /// The same for the background.
    #[serde(default = "gratings_only")]
    pub background_texture_weights: [f64; 4],
    /// Probability that a surface gets a smooth brightness gain ([`super::Shading`]). Default 0.
    #[serde(default)]
    pub shading_prob: f64,
    /// When set, each scene draws its smallest disparity from `[lo, hi]` instead of using
    /// `min_disparity`: scenes whose far end is near (rooms, table tops, Middlebury), where every
    /// point has a large disparity and the band of the left view that the right view cannot see is
    /// wide. Drawn from a stream of its own, so the scene's other draws are the same. Default: unset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_disparity_range: Option<[f64; 2]>,
    /// Probability that a scene gets a lattice ([`Outline::Lattice`](crate::synthetic::surface::Outline::Lattice): a trellis or fence in front,
    /// the scene seen through its holes). Drawn from a stream of its own, so the scene's other
    /// draws are the same. Default 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lattice_prob: f64,
    /// A folder of photographs ([`super::PhotoLibrary`]); with [`Self::photo_prob`], surfaces
    /// and backgrounds take textures cut from them. Default: unset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo_dir: Option<std::path::PathBuf>,
    /// Probability that a surface (or the background) is textured with a photograph of
    /// [`Self::photo_dir`] instead of its procedural kind; drawn after the kind, so with 0 (the
    /// default) the scenes are those of the procedural generator, bit for bit.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub photo_prob: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn gratings_only() -> [f64; 4] {
    [1.0, 0.0, 0.0, 0.0]
}

/// A named texture mix for [`SyntheticConfig::with_textures`] (the `textures` key of a training
/// source).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TexturePreset {
    /// Full-contrast gratings and noise on every surface, no shading: the original generator.
    #[default]
    Smooth,
    /// Foreground 35 % gratings, 35 % dead leaves, 15 % flat, 15 % low contrast; background
    /// 25 %, 35 %, 20 %, 20 %; half the surfaces shaded.
    Rich,
}

impl Default for SyntheticConfig {
    fn default() -> Self {
        Self {
            width: 640,
            height: 384,
            min_surfaces: 3,
            max_surfaces: 10,
            min_disparity: 1.0,
            max_disparity: 96.0,
            max_slant: 0.3,
            kind_weights: [0.3, 0.3, 0.2, 0.2],
            min_wavelength: 4.0,
            max_wavelength: 64.0,
            texture_weights: gratings_only(),
            background_texture_weights: gratings_only(),
            shading_prob: 0.0,
            min_disparity_range: None,
            lattice_prob: 0.0,
            photo_dir: None,
            photo_prob: 0.0,
        }
    }
}

impl SyntheticConfig {
    /// The default configuration at another size, disparities scaled with the width
    /// (`max_disparity = 0.15 · width`, at least 4).
    pub fn with_size(width: usize, height: usize) -> Self {
        Self { width, height, max_disparity: (0.15 * width as f64).max(4.0), ..Self::default() }
    }

    /// [`Self::with_size`] with the [`TexturePreset::Rich`] texture mix.
    pub fn rich(width: usize, height: usize) -> Self {
        Self::with_size(width, height).with_textures(TexturePreset::Rich)
    }

    /// This configuration with the texture mix (weights and shading) of `preset`.
    pub fn with_textures(self, preset: TexturePreset) -> Self {
        match preset {
            TexturePreset::Smooth => Self {
                texture_weights: gratings_only(),
                background_texture_weights: gratings_only(),
                shading_prob: 0.0,
                ..self
            },
            TexturePreset::Rich => Self {
                texture_weights: [0.35, 0.35, 0.15, 0.15],
                background_texture_weights: [0.25, 0.35, 0.2, 0.2],
                shading_prob: 0.5,
                ..self
            },
        }
    }
}
