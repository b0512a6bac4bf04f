//! [`SyntheticScenes`]: the keys of a procedural scene mix, shared by a synthetic training source
//! and the validation set, and its [`PhotoTextures`].

use std::path::PathBuf;

use dgstereo_core::{Error, Problem, Result};
use dgstereo_data::SyntheticConfig;
use dgstereo_data::synthetic::TexturePreset;
use serde::{Deserialize, Serialize};

/// The scene keys of a synthetic source and of the validation set, written once: both tables
/// flatten this struct, so they read the same keys with the same defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SyntheticScenes {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Largest disparity; default `0.15 · width`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_disparity: Option<f64>,
    /// Texture mix: `"smooth"` (default: full-contrast gratings on every surface, the original
    /// generator) or `"rich"` (adds dead-leaves shapes with sharp edges, flat and low-contrast
    /// surfaces, and shading; `SyntheticConfig::rich` of the data crate).
    #[serde(skip_serializing_if = "is_smooth", deserialize_with = "texture_preset")]
    pub textures: TexturePreset,
    /// `[lo, hi]`: each scene draws its smallest disparity from this range (scenes whose far end
    /// is near, with wide bands at the left border that the right view cannot see); default:
    /// every scene's far end is at disparity 1.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_disparity: Option<[f64; 2]>,
    /// Surfaces textured with crops of real photographs (`{ dir = "...", share = 0.5 }`);
    /// default: procedural textures only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub photos: Option<PhotoTextures>,
}

impl Default for SyntheticScenes {
    fn default() -> Self {
        Self {
            width: 640,
            height: 384,
            max_disparity: None,
            textures: TexturePreset::Smooth,
            min_disparity: None,
            photos: None,
        }
    }
}

impl SyntheticScenes {
    /// Everything wrong with the values without reading files, keys relative to the holding
    /// table: `max_disparity` finite and > 1, `min_disparity` `[lo, hi]` with
    /// `0 < lo <= hi < max_disparity - 1` (against the default `0.15 · width` when unset), and
    /// the photo share.
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        if let Some(m) = self.max_disparity.filter(|m| !(m.is_finite() && *m > 1.0)) {
            problems.push(Problem::new("max_disparity", format!("{m}: must be a finite value > 1")));
        }
        let max = self.max_disparity.unwrap_or(0.15 * self.width as f64);
        if let Some([lo, hi]) = self.min_disparity
            && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi && hi < max - 1.0)
        {
            problems.push(Problem::new(
                "min_disparity",
                format!("[{lo}, {hi}]: expected [lo, hi] with 0 < lo <= hi < max_disparity - 1 ({})", max - 1.0),
            ));
        }
        if let Some(p) = &self.photos {
            problems.extend(p.problems().into_iter().map(|p| p.within("photos")));
        }
        problems
    }

    /// Checks that the photo folder's photographs load (they are decoded once per process, so
    /// the generator later finds them cached); keys relative to the holding table.
    ///
    /// # Errors
    /// [`Error::Config`] naming `photos.dir`.
    pub fn check_files(&self) -> Result<()> {
        match &self.photos {
            Some(p) => p.check_folder().map_err(|e| e.within("photos")),
            None => Ok(()),
        }
    }

    /// The generator's settings: the default scene mix at `[width, height]`, the texture
    /// preset, the disparity range, the photo textures, and the share of scenes with a lattice.
    pub fn synthetic(&self, lattices: Option<f64>) -> SyntheticConfig {
        let mut config = SyntheticConfig::with_size(self.width, self.height).with_textures(self.textures);
        if let Some(m) = self.max_disparity {
            config.max_disparity = m;
        }
        config.min_disparity_range = self.min_disparity;
        config.lattice_prob = lattices.unwrap_or(0.0);
        if let Some(p) = &self.photos {
            config.photo_dir = Some(p.dir.clone());
            config.photo_prob = p.share;
        }
        config
    }
}

fn is_smooth(t: &TexturePreset) -> bool {
    *t == TexturePreset::Smooth
}

/// Reads `textures`, naming the key in the error (errors inside a flattened or internally
/// tagged table otherwise only point at the table).
fn texture_preset<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<TexturePreset, D::Error> {
    use serde::de::{Error as _, IntoDeserializer, value};
    let name = String::deserialize(d).map_err(|e| D::Error::custom(format!("textures: {e}")))?;
    TexturePreset::deserialize(IntoDeserializer::<value::Error>::into_deserializer(name.as_str()))
        .map_err(|e| D::Error::custom(format!("textures = \"{name}\": {e}")))
}

/// Photo textures of a synthetic source or the validation set (`photos = { dir, share }`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotoTextures {
    /// The folder of photographs (`scripts/fetch-photo-textures.sh` fills `data/photos/train` and
    /// `data/photos/held-out`).
    pub dir: PathBuf,
    /// Share of the surfaces (and backgrounds) textured with a photograph, in (0, 1].
    pub share: f64,
}

impl PhotoTextures {
    /// Everything wrong with the share, keys relative to the `photos` table.
    pub fn problems(&self) -> Vec<Problem> {
        if self.share > 0.0 && self.share <= 1.0 {
            Vec::new()
        } else {
            vec![Problem::new("share", format!("{}: must be a share in (0, 1]", self.share))]
        }
    }

    /// Checks that the folder's photographs load.
    ///
    /// # Errors
    /// [`Error::Config`] naming `dir`.
    fn check_folder(&self) -> Result<()> {
        dgstereo_data::synthetic::PhotoLibrary::of_folder(&self.dir)
            .map(|_| ())
            .map_err(|e| Error::config("dir", e.to_string()))
    }
}
